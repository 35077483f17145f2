#!/usr/bin/python3
"""Integration tests that run the microbsdf binary (single rank and under mpirun).

Usage: cli_test.py BUILD_DIR SOURCE_DIR TEST_NAME
Each test prints what it checked and exits non-zero on failure. Every subprocess has a timeout.
"""
import hashlib
import json
import os
import shutil
import subprocess
import sys
import tempfile

import h5py
import numpy as np

BUILD, SRC, NAME = sys.argv[1], sys.argv[2], sys.argv[3]
EXE = os.path.join(BUILD, "microbsdf")
ENV = dict(os.environ, OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1",
           OMPI_MCA_rmaps_base_oversubscribe="1")
TMP = tempfile.mkdtemp(prefix="microbsdf_" + NAME + "_")


def run(args, timeout=300, expect=0, mpi=0):
    cmd = ([shutil.which("mpirun"), "-np", str(mpi), "--oversubscribe"] if mpi else []) + [EXE] + args
    p = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, env=ENV, cwd=TMP)
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
    """SHA-256 of the raw bytes of every /bsdf and /bsdf_stderr dataset."""
    out = {}
    with h5py.File(path, "r") as f:
        for g in ("bsdf", "bsdf_stderr"):
            for k, d in f[g].items():
                out[f"{g}/{k}"] = hashlib.sha256(np.ascontiguousarray(d[()]).tobytes()).hexdigest()
    return out


def sha(path):
    return hashlib.sha256(open(path, "rb").read()).hexdigest()


def test_mpi_smoke():
    job = small_job(os.path.join(TMP, "job.toml"))
    run(["run", job, "-o", "mpi.h5"], mpi=2, timeout=300)
    info = json.loads(run(["info", "mpi.h5", "--json"]).stdout)
    assert info["complete"], info
    assert info["done_count"] == 5
    for s in info["slices"]:
        refl = s["energy"]["reflected"]
        gm = np.array(refl["coherent"]) + np.array(refl["multiple"])
        assert np.all(gm > 0.1) and np.all(gm <= 1.0 + 1e-9), gm  # gold: ~0.35 at 450 nm, ~0.95 at 650 nm
        assert np.all(np.isfinite(s["energy"]["total"]))
    logs = os.listdir(os.path.join(TMP, "mpi.h5.logs"))
    assert sorted(logs) == ["mpi.rank0.log", "mpi.rank1.log"], logs
    print("mpirun -np 2: complete, WM energies", [round(np.mean(s["energy"]["total"]), 4) for s in info["slices"]])


def test_quickstart_job():
    shutil.copy(os.path.join(SRC, "jobs", "quickstart.toml"), TMP)
    run(["run", "quickstart.toml", "-o", "q.h5"], mpi=2, timeout=600)
    info = json.loads(run(["info", "q.h5", "--json"]).stdout)
    assert info["complete"], info
    print("quickstart: complete;", info["done_count"], "slices")


def test_determinism():
    job = small_job(os.path.join(TMP, "job.toml"))
    run(["run", job, "-o", "t1.h5", "--threads", "1"])
    run(["run", job, "-o", "t2.h5", "--threads", "2"])
    run(["run", job, "-o", "n2.h5", "--threads", "1"], mpi=2)
    a, b, c = datasets(os.path.join(TMP, "t1.h5")), datasets(os.path.join(TMP, "t2.h5")), datasets(os.path.join(TMP, "n2.h5"))
    assert a == b, "1 vs 2 threads differ"
    assert a == c, "1 rank vs 2 ranks differ"
    print("byte-identical datasets for 1 thread, 2 threads and 2 ranks:", sorted(a))


def test_slice_export():
    job = small_job(os.path.join(TMP, "job.toml"))
    run(["run", job, "-o", "s.h5"])
    run(["slice", "s.h5", "--theta-i", "20", "--phi-i", "10", "--model", "GM", "-o", "s.csv"])
    run(["slice", "s.h5", "--theta-i", "20", "--phi-i", "10", "--model", "GS", "-o", "s.exr", "--size", "64"])
    assert os.path.getsize(os.path.join(TMP, "s.exr")) > 1000
    rows = np.genfromtxt(os.path.join(TMP, "s.csv"), delimiter=",", names=True, skip_header=1)
    albedo = np.sum(rows["f_450nm"] * rows["projected_solid_angle_sr"])
    info = json.loads(run(["info", "s.h5", "--json"]).stdout)
    refl = info["slices"][1]["energy"]["reflected"]
    expected = refl["coherent"][0] + refl["multiple"][0]
    assert abs(albedo - expected) < 1e-6 * max(1.0, expected), (albedo, expected)
    # GM = coherent + multiple
    with h5py.File(os.path.join(TMP, "s.h5"), "r") as f:
        gm = f["bsdf/coherent"][1, 0, :] + f["bsdf/multiple"][1, 0, :]
    assert np.allclose(np.sort(gm[gm > 0])[-5:], np.sort(rows["f_450nm"])[-5:], rtol=1e-6)
    # The default components are the paper's WM: all four models can be exported.
    for model in ("GS", "WS", "WM", "incoherent"):
        run(["slice", "s.h5", "--theta-i", "20", "--model", model, "-o", f"{model}.csv"])
    r = run(["slice", "s.h5", "--theta-i", "20", "--model", "lost", "-o", "x.csv"], expect=2)
    assert "lost" in r.stderr, r.stderr
    print("slice: CSV albedo", albedo, "matches info", expected)


def test_bad_input():
    out = os.path.join(TMP, "keep.h5")
    good = small_job(os.path.join(TMP, "good.toml"), output="keep.h5")
    run(["run", good])
    before = sha(out)
    mesh_nan = os.path.join(TMP, "nan.obj")
    open(mesh_nan, "w").write("v 0 0 0\nv 1 0 0\nv 1 1 nan\nf 1 2 3\n")
    mesh_empty = os.path.join(TMP, "empty.ply")
    open(mesh_empty, "w").write("ply\nformat ascii 1.0\nelement vertex 0\nproperty float x\nproperty float y\n"
                                "property float z\nelement face 0\nproperty list uchar int vertex_indices\nend_header\n")
    cases = {
        "malformed.toml": ("[geometry\nkind = 1\n", "malformed.toml:1"),
        "unknown.toml": ("[geometry]\nkind = \"flat\"\ncolour = \"red\"\n", "geometry.colour"),
        "nomesh.toml": ("[geometry]\nkind = \"mesh\"\nfile = \"missing.obj\"\n", "missing.obj"),
        "nanmesh.toml": ("[geometry]\nkind = \"mesh\"\nfile = \"nan.obj\"\n", "nan.obj:3"),
        "emptymesh.toml": ("[geometry]\nkind = \"mesh\"\nfile = \"empty.ply\"\n", "empty"),
        "negsize.toml": ("[geometry]\nkind = \"flat\"\nsize_um = [-5.0, 5.0]\n", "geometry.size_um"),
        "lambda.toml": ("[material]\nname = \"Cu\"\n[spectrum]\nwavelengths_nm = [200.0]\n", "spectrum.wavelengths_nm"),
    }
    for name, (text, needle) in cases.items():
        path = os.path.join(TMP, name)
        open(path, "w").write(text + '\n[output]\npath = "keep.h5"\n')
        for mpi in (0, 2):
            r = run(["run", path], expect=2, mpi=mpi, timeout=120)
            msg = r.stderr + r.stdout
            assert needle in msg, f"{name}: '{needle}' not in: {msg}"
            if mpi:
                assert msg.count("[error]") == 1, f"{name}: expected one error message under MPI: {msg}"
            assert sha(out) == before, f"{name} changed the existing output"
        print(f"{name}: exit 2, message names '{needle}', output untouched (1 rank and 2 ranks)")


def test_geometry_export():
    job = small_job(os.path.join(TMP, "job.toml"))
    run(["geometry", job, "-o", "patch.ply"])
    head = open(os.path.join(TMP, "patch.ply"), "rb").read(200)
    assert head.startswith(b"ply\nformat binary_little_endian"), head
    # The exported patch loads back as a mesh job and gives the same geometry hash.
    small_job(os.path.join(TMP, "mesh.toml"), geometry='kind = "mesh"\nfile = "patch.ply"\nsize_um = [10.0, 10.0]\n',
              output="mesh.h5")
    r = run(["check", "mesh.toml"])
    assert "ok" in r.stdout, r.stdout
    print("geometry: PLY written and reloaded:", r.stdout.strip().splitlines()[1])


TESTS = {n[5:]: f for n, f in globals().items() if n.startswith("test_")}
try:
    TESTS[NAME]()
finally:
    shutil.rmtree(TMP, ignore_errors=True)
print("1 passed, 0 failed")
