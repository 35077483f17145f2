#!/usr/bin/python3
"""What the integration tests share: the binary under test, a scratch folder, runs with timeouts,
small jobs and dataset digests.

A test file imports this module, defines test_<name>() functions and ends with run_selected(globals()):
    python3 cli_test.py BUILD_DIR SOURCE_DIR TEST_NAME
Each test prints what it checked and exits non-zero on failure. Every subprocess has a timeout.
"""
import hashlib
import signal
import time
import json
import os
import re
import shutil
import subprocess
import sys
import struct
import tempfile

import h5py
import matplotlib
matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np

BUILD, SRC, NAME = sys.argv[1], sys.argv[2], sys.argv[3]
EXE = os.path.join(BUILD, "microbsdf")
ENV = dict(os.environ, OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1",
           OMPI_MCA_rmaps_base_oversubscribe="1")
# For mpirun: munge is installed for the Slurm tests, but its daemon runs only while they do, and
# PMIx's munge plugin retries an absent daemon for 2.3 s at every mpirun start (docs/running.md).
MPI_ENV = dict(ENV, PMIX_MCA_psec="^munge")
TMP = tempfile.mkdtemp(prefix="microbsdf_" + NAME + "_")


def run(args, timeout=300, expect=0, mpi=0):
    cmd = ([shutil.which("mpirun"), "-np", str(mpi), "--oversubscribe"] if mpi else []) + [EXE] + args
    p = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, env=MPI_ENV if mpi else ENV, cwd=TMP)
    if expect is not None and p.returncode != expect:
        sys.exit(f"FAIL: {' '.join(cmd)} exited {p.returncode}, expected {expect}\n{p.stdout}\n{p.stderr}")
    return p


def small_job(path, extra="", output="out.h5", geometry=None):
    geometry = geometry or ('kind = "hemispheres"\nsize_um = [10.0, 10.0]\nradius_um = 2.0\n'
                            'spacing_um = 5.0\nresolution_um = 0.25\n')
    with open(path, "w") as f:
        f.write(f"""[geometry]
{geometry}
[material]
name = "Au"
[spectrum]
wavelengths_nm = [450.0, 650.0]
[directions]
n_theta = 12
n_phi = 24
incidence = [[0.0, 0.0], [20.0, 10.0], [45.0, 90.0], [70.0, 200.0], [85.0, 300.0]]
[sampling]
paths_per_slice = 20000
seed = 7
[output]
path = "{output}"
{extra}""")
    return path


def datasets(path):
    """SHA-256 of the raw bytes of every table dataset (/bsdf, /bsdf_stderr and, in a float16 file,
    their scales)."""
    out = {}
    with h5py.File(path, "r") as f:
        for g in ("bsdf", "bsdf_stderr", "bsdf_scale", "bsdf_stderr_scale"):
            if g not in f:
                continue
            for k, d in f[g].items():
                out[f"{g}/{k}"] = hashlib.sha256(np.ascontiguousarray(d[()]).tobytes()).hexdigest()
    return out


def sha(path):
    return hashlib.sha256(open(path, "rb").read()).hexdigest()


def full_sphere_job(name, output_extra, n_theta=4, n_phi=8, wavelengths="[500.0, 650.0]", paths=20000, seed=1):
    """TMP/<name>.toml: a rough gold patch (gaussian, rms 0.4 µm, correlation 1 µm) with every upper
    bin an incidence (incidence = "all"), coherent and multiple, writing <name>.h5 with the given
    [output] lines: the job whose pairs of incidence bins the storage tests fold."""
    path = os.path.join(TMP, name + ".toml")
    with open(path, "w") as f:
        f.write(f"""[geometry]
kind = "gaussian"
size_um = [10.0, 10.0]
rms_um = 0.4
correlation_um = 1.0
[material]
name = "Au"
[spectrum]
wavelengths_nm = {wavelengths}
[directions]
n_theta = {n_theta}
n_phi = {n_phi}
incidence = "all"
[effects]
components = ["coherent", "multiple"]
[sampling]
paths_per_slice = {paths}
seed = {seed}
[output]
path = "{name}.h5"
{output_extra}
""")
    return path


def many_tiles_job(path, n_theta, output, paths=20000):
    """A job with n_theta x 4 incidence directions on a small patch (each tile a fraction of a second)."""
    inc = ", ".join(f"[{t:.2f}, {p:.1f}]" for t in np.linspace(0, 80, n_theta) for p in (0, 45, 90, 135))
    with open(path, "w") as f:
        f.write(f"""[geometry]
kind = "hemispheres"
size_um = [5.0, 5.0]
radius_um = 2.0
spacing_um = 5.0
resolution_um = 0.25
[material]
name = "Al"
[spectrum]
wavelengths_nm = [450.0, 650.0]
[directions]
n_theta = 10
n_phi = 20
incidence = [{inc}]
[effects]
components = ["coherent", "incoherent", "multiple"]
[sampling]
paths_per_slice = {paths}
wave_samples_per_bin = 64
[output]
path = "{output}"
""")
    return path


def journal_count(out):
    try:
        return sum(1 for _ in open(out + ".journal"))
    except FileNotFoundError:
        return 0


def start(args, mpi=2):
    cmd = [shutil.which("mpirun"), "-np", str(mpi), "--oversubscribe", EXE] + args
    return subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=MPI_ENV, cwd=TMP,
                            start_new_session=True)


def wait_for(proc, out, fraction, total, timeout=300):
    t0 = time.time()
    while journal_count(out) < fraction * total:
        if proc.poll() is not None:
            return False
        if time.time() - t0 > timeout:
            sys.exit("FAIL: timeout waiting for progress")
        time.sleep(0.02)
    return True


def wait_session_gone(sid, timeout=60):
    """Waits until no process of the session is left (ranks outlive mpirun for a moment)."""
    t0 = time.time()
    while subprocess.run(["pgrep", "-s", str(sid)], capture_output=True).returncode == 0:
        assert time.time() - t0 < timeout, "processes of the killed job are still running"
        time.sleep(0.05)



def run_selected(namespace):
    """Runs the test named on the command line; prints the closing line CTest's log shows."""
    tests = {n[5:]: f for n, f in namespace.items() if n.startswith("test_")}
    try:
        tests[NAME]()
    finally:
        shutil.rmtree(TMP, ignore_errors=True)
    print("1 passed, 0 failed")
