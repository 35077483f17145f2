#!/usr/bin/python3
"""Fault injection: what a cluster does to a run every day, and what the program must do about it.

Usage: faults_test.py BUILD_DIR SOURCE_DIR TEST_NAME (see harness.py).
Each test asserts the exit code, the message, and that a good output already at the path is
byte-identical afterwards. No test waits for a fixed time to pass: each waits for an observable
state (a journal line, a log line, a process gone), with a timeout only as a bound.
"""
import json
import os
import resource
import shutil
import signal
import subprocess
import sys
import time

import h5py
import numpy as np

from harness import *  # noqa: F401,F403 (BUILD, SRC, EXE, ENV, TMP, run, small_job, datasets, ...)

EXIT_BAD_INPUT, EXIT_STOPPED, EXIT_WRITE_FAILED, EXIT_BUSY = 2, 3, 4, 5


def good_output(name, job=None):
    """A finished output at `name` (the run that must never damage it) and its bytes' digest."""
    job = job or small_job(os.path.join(TMP, "good.toml"))
    run(["run", job, "-o", name])
    return sha(os.path.join(TMP, name))


def expect(args, code, *phrases, mpi=0, timeout=300):
    p = run(args, expect=code, mpi=mpi, timeout=timeout)
    text = p.stdout + p.stderr
    for phrase in phrases:
        assert phrase in text, f"{' '.join(args)}: '{phrase}' not in the output:\n{text}"
    assert "MPI_ABORT" not in text, f"{' '.join(args)} aborted instead of exiting:\n{text}"
    return text

# The uninterrupted pilot of test_pilot_signal takes minutes; a stop that is answered at all ends
# far sooner. The answer time (signal to stop, as the program measures it) is printed, not asserted:
# on a loaded machine a process may wait for a core however promptly it polls.
PHASE_SECONDS = 60


def answered(text, message):
    """Seconds from the signal to the stop, as the program reports it in `message (answered X s ...)`."""
    m = re.search(re.escape(message) + r" \(answered ([0-9.]+) s after the signal\)", text)
    assert m, f"'{message} (answered ... s after the signal)' not in the output:\n{text}"
    return float(m.group(1))


def killed_partial(job, out):
    """A run killed (SIGKILL, rank and mpirun) after its first finished slice: a resumable partial."""
    p = start(["run", job, "-o", out], mpi=1)
    t0 = time.time()
    while journal_count(os.path.join(TMP, out)) < 1:
        assert p.poll() is None, "the run ended before the kill"
        assert time.time() - t0 < 120, "no slice finished"
        time.sleep(0.02)
    subprocess.run(["pkill", "-KILL", "-s", str(p.pid)])
    p.wait()
    wait_session_gone(p.pid)
    assert os.path.exists(os.path.join(TMP, out + ".partial"))


def mount_tmpfs(path, size):
    os.makedirs(path, exist_ok=True)
    return subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", path],
                          capture_output=True).returncode == 0


def test_disk_full_during_fold():
    """A file system with room for the run's partial file but not for the fold of pairs stored once
    (pairs = "once"): exit 4 naming ENOSPC, no crash, the partial file and its journal kept, the fold's
    files removed; --resume where there is room folds into the same table as a clean run."""
    job = full_sphere_job("fold", 'profile = "compact"', n_theta=16, n_phi=64,
                          wavelengths="{ min = 400.0, max = 700.0, count = 8 }", paths=2000)
    run(["run", job, "-o", "ref.h5"])
    disk = os.path.join(TMP, "disk")
    # The partial file takes 8.5 MB (its per-bin errors, which the fold rounds the means with and
    # drops); the fold needs the final file's 3.4 MB and its scratch file more.
    partial = 8448 * 1024
    if not mount_tmpfs(disk, f"{partial * 13 // 10 // 1024}k"):
        sys.exit("FAIL: cannot mount a tmpfs (the test needs root, as CI has)")
    try:
        expect(["run", job, "-o", "disk/out.h5"], EXIT_WRITE_FAILED, "No space left on device (ENOSPC)",
               "1024/1024 slices are safe in", "--resume")
        left = sorted(os.listdir(disk))
        assert left == ["out.h5.journal", "out.h5.logs", "out.h5.partial"], left
        for name in ("out.h5.journal", "out.h5.partial"):
            shutil.copy(os.path.join(disk, name), os.path.join(TMP, name))
    finally:
        subprocess.run(["umount", disk], capture_output=True)
    r = run(["run", job, "-o", "out.h5", "--resume"])
    assert "1024 of 1024 slices already complete" in r.stdout + r.stderr
    assert datasets(os.path.join(TMP, "out.h5")) == datasets(os.path.join(TMP, "ref.h5"))
    print("full disk during the fold: exit 4 (ENOSPC), partial file and journal kept; resumed: the same table")


def test_disk_full():
    """A full output file system: exit 4 naming the file and ENOSPC, the old output untouched, the
    partial file resumable once there is room, and the resumed table identical to a clean run."""
    job = small_job(os.path.join(TMP, "job.toml"), extra="", output="x.h5")
    with open(job) as f:
        # Tables larger than the grid's axes, so that a disk of 1.6 times the file holds the axes and
        # a few slices (every bit stored: the tables rounded to their noise are a third of the size).
        text = f.read().replace("n_theta = 12\nn_phi = 24", "n_theta = 60\nn_phi = 120").replace(
            "[output]", '[output]\nrounding = "none"')
    with open(job, "w") as f:
        f.write(text)
    run(["run", job, "-o", "ref.h5"])
    ref = sha(os.path.join(TMP, "ref.h5"))
    size = os.path.getsize(os.path.join(TMP, "ref.h5"))
    disk = os.path.join(TMP, "disk")
    if mount_tmpfs(disk, f"{size * 16 // 10 // 1024}k"):
        how = "a tmpfs of 1.6x the file's size holding an old output of the same size"
    else:
        sys.exit("FAIL: cannot mount a tmpfs (the test needs root, as CI has)")
    try:
        shutil.copy(os.path.join(TMP, "ref.h5"), os.path.join(disk, "out.h5"))
        text = expect(["run", job, "-o", "disk/out.h5"], EXIT_WRITE_FAILED, "No space left on device (ENOSPC)",
                      "disk/out.h5.partial", "--resume", "was not changed")
        assert sha(os.path.join(disk, "out.h5")) == ref, "the old output was damaged"
        journaled = journal_count(os.path.join(disk, "out.h5"))
        # Room again (the old output goes): --resume completes it, identical to an uninterrupted run.
        os.remove(os.path.join(disk, "out.h5"))
        run(["run", job, "-o", "disk/out.h5", "--resume"])
        assert datasets(os.path.join(disk, "out.h5")) == datasets(os.path.join(TMP, "ref.h5"))
        # The log folder on the full disk: the run stops with exit 4 too (log writes are checked).
        subprocess.run(["dd", "if=/dev/zero", f"of={disk}/filler", "bs=4k"], capture_output=True)
        expect(["run", job, "-o", "logfull.h5", "--log-dir", "disk/logs"], EXIT_WRITE_FAILED)
    finally:
        subprocess.run(["umount", disk], capture_output=True)
    print(f"disk full ({how}): exit 4 with ENOSPC named, {journaled} slices journaled, old output "
          "byte-identical; --resume completed it identical to a clean run; a full log folder: exit 4")


def test_file_size_limit():
    """A file-size limit (ulimit -f) below the output's size: exit 4 naming the partial file and
    EFBIG (not SIGXFSZ's silent kill, exit 153), the old output byte-identical, and --resume without
    the limit completing a table identical to a clean run."""
    job = small_job(os.path.join(TMP, "job.toml"), output="out.h5")
    ref = good_output("out.h5", job)
    limit = os.path.getsize(os.path.join(TMP, "out.h5")) // 2

    def limited():
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))

    p = subprocess.run([EXE, "run", job, "-o", "out.h5"], capture_output=True, text=True, timeout=300, env=ENV,
                       cwd=TMP, preexec_fn=limited)
    text = p.stdout + p.stderr
    assert p.returncode == EXIT_WRITE_FAILED, f"exit {p.returncode} under ulimit -f:\n{text}"
    assert "File too large (EFBIG)" in text and "out.h5.partial" in text, text
    assert sha(os.path.join(TMP, "out.h5")) == ref, "the old output was damaged"
    run(["run", job, "-o", "fresh.h5"])
    run(["run", job, "-o", "out.h5", "--resume"])
    assert datasets(os.path.join(TMP, "out.h5")) == datasets(os.path.join(TMP, "fresh.h5"))
    print(f"ulimit -f {limit} bytes: exit 4 naming EFBIG, the old output byte-identical; --resume completed it "
          "identical to a clean run")


def test_runaways():
    """paths_per_slice = 1e15 on a flat mirror: the run's memory stays what a small job needs (its
    batches of paths are made as they are traced, not listed first: 90 GB) and a SIGTERM stops it
    cleanly with exit 3. /dev/zero as a job file: refused at once with exit 2 (it was read until
    memory ran out). A heightfield of heights 5e28 um: exit 2 naming the key (Embree aborted)."""
    job = os.path.join(TMP, "huge.toml")
    with open(job, "w") as f:
        f.write("""[geometry]\nkind = "flat"\n[material]\nname = "mirror"\n[spectrum]\nwavelengths_nm = [550.0]
[directions]\nn_theta = 8\nn_phi = 16\nincidence = [[30.0, 0.0]]\n[effects]\ncomponents = ["coherent", "multiple"]
[sampling]\npaths_per_slice = 1000000000000000\n""")
    p = subprocess.Popen([EXE, "run", job, "-o", "huge.h5"], stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                         text=True, env=ENV, cwd=TMP)
    peak_kb = 0
    for _ in range(40):  # 4 s of tracing
        time.sleep(0.1)
        with open(f"/proc/{p.pid}/status") as f:
            peak_kb = max([peak_kb] + [int(x.split()[1]) for x in f if x.startswith("VmHWM:")])
    p.send_signal(signal.SIGTERM)
    out, _ = p.communicate(timeout=120)
    print(f"paths_per_slice 1e15: peak resident {peak_kb / 1024:.0f} MB after 4 s; exit {p.returncode} on SIGTERM")
    assert p.returncode == EXIT_STOPPED, out
    assert peak_kb < 1024 * 1024, f"peak resident {peak_kb} kB"
    for command in (["check", "/dev/zero"], ["run", "/dev/zero", "-o", "zero.h5"]):
        expect(command, EXIT_BAD_INPUT, "/dev/zero: larger than 16 MiB")
    # Finite but enormous heights (1e30 x height_scale 0.05): refused naming the key and the vertex,
    # before Embree (whose bounds assertion aborted the run with a core dump).
    sys.path.insert(0, os.path.join(SRC, "python"))
    from topography_files import write_exr
    write_exr(os.path.join(TMP, "tall.exr"), np.full((8, 8), 1e30, np.float32))
    tall = small_job(os.path.join(TMP, "tall.toml"), output="tall.h5",
                     geometry='kind = "heightfield"\nfile = "tall.exr"\ntexel_um = 0.5\nheight_scale = 0.05\n')
    for command in (["check", tall], ["run", tall, "-o", "tall.h5"]):
        expect(command, EXIT_BAD_INPUT, "geometry.file", "beyond the 1e6 µm")


def test_damaged_partials():
    """--resume of a partial file that is truncated or overwritten with garbage: exit 2 naming the
    file and what to do, no MPI_ABORT (it was exit 1 with an abort banner). A slice whose `done` flag
    and journal line were forged over rows never written: computed again, with a warning, and the
    finished table identical to a clean run with no NaN."""
    job = small_job(os.path.join(TMP, "job.toml"), output="out.h5")
    run(["run", job, "-o", "ref.h5"])
    for damage in ("truncated", "garbage"):
        out = f"{damage}.h5"
        killed_partial(job, out)
        partial = os.path.join(TMP, out + ".partial")
        size = os.path.getsize(partial)
        with open(partial, "r+b") as f:
            if damage == "truncated":
                f.truncate(size // 3)
            else:
                f.seek(size // 4)
                f.write(np.random.default_rng(1).bytes(size // 2))
        expect(["run", job, "-o", out, "--resume"], EXIT_BAD_INPUT, f"cannot resume {out}.partial", "damaged",
               f"Remove {out}.partial", mpi=2)
    out = "forged.h5"
    killed_partial(job, out)
    partial = os.path.join(TMP, out + ".partial")
    subprocess.run(["h5clear", "-s", partial], check=True, capture_output=True)
    with h5py.File(partial, "r+") as h:
        done = h["/bsdf/done"][:]
        forged = int(np.flatnonzero(done == 0)[0])
        done[forged] = 1
        h["/bsdf/done"][:] = done
    with open(partial[:-len(".partial")] + ".journal", "a") as f:
        f.write(f"tile {forged}\n")
    text = expect(["run", job, "-o", out, "--resume"], 0, f"slice {forged} is marked done", "computing it again",
                  mpi=2)
    assert datasets(os.path.join(TMP, out)) == datasets(os.path.join(TMP, "ref.h5")), "the resumed table differs"
    with h5py.File(os.path.join(TMP, out), "r") as h:
        assert all(np.all(np.isfinite(h["/bsdf/" + c][...])) for c in h["/bsdf"] if c != "done")
    print(f"truncated and garbage partials: exit 2 naming the file; a forged done flag (slice {forged}): computed "
          "again, the table identical to a clean run")


def kept_slices(out):
    """The slices the journal of `out` lists as done."""
    with open(os.path.join(TMP, out + ".journal")) as f:
        return [int(line.split()[1]) for line in f if line.startswith("tile ")]


def test_damaged_kept_slices():
    """--resume verifies every slice it keeps: a flipped byte in a deflated table chunk (Adler-32), in
    a chunk of the per-slice statistics (Fletcher-32), and a NaN or negative value written with valid
    checksums into a kept slice's table: each slice is computed again with a warning naming it and
    the dataset, and the finished table is identical to a clean run (the resume kept them before: a
    finished table with NaN, exit 0, or a refusal of the whole partial file)."""
    job = small_job(os.path.join(TMP, "job.toml"), output="out.h5")
    run(["run", job, "-o", "ref.h5"])
    with h5py.File(os.path.join(TMP, "ref.h5"), "r") as h:
        table = "/bsdf/" + next(c for c in ("coherent", "multiple", "geo_masked") if c in h["/bsdf"])

    def flip(partial, dataset, t):
        with h5py.File(partial, "r") as h:
            d = h[dataset]
            info = d.id.get_chunk_info_by_coord((t,) + (0,) * (d.ndim - 1))
        with open(partial, "r+b") as f:
            f.seek(info.byte_offset + info.size // 2)
            b = f.read(1)
            f.seek(info.byte_offset + info.size // 2)
            f.write(bytes([b[0] ^ 0x5A]))

    def overwrite(partial, dataset, t, value):
        with h5py.File(partial, "r+") as h:
            row = h[dataset][t]
            row.flat[len(row.flat) // 2] = value
            h[dataset][t] = row

    cases = [("table chunk", lambda p, t: flip(p, table, t), "cannot be read back", table),
             ("statistics chunk", lambda p, t: flip(p, "/stats/samples", t), "cannot be read back", "/stats/samples"),
             ("NaN in a table", lambda p, t: overwrite(p, table, t, np.nan), "cannot have written", table),
             ("negative value", lambda p, t: overwrite(p, table, t, -1.0), "cannot have written", table)]
    for name, damage, phrase, dataset in cases:
        out = name.replace(" ", "_") + ".h5"
        killed_partial(job, out)
        partial = os.path.join(TMP, out + ".partial")
        subprocess.run(["h5clear", "-s", partial], check=True, capture_output=True)
        t = kept_slices(out)[0]
        damage(partial, t)
        text = expect(["run", job, "-o", out, "--resume"], 0, f"slice {t} is marked done", phrase, dataset,
                      "computing it again", mpi=2)
        assert datasets(os.path.join(TMP, out)) == datasets(os.path.join(TMP, "ref.h5")), f"{name}: the table differs"
        print(f"{name} of kept slice {t}: computed again with a warning naming {dataset}; the table identical to a "
              "clean run")


def rank_pids(session):
    """{MPI rank: PID} of the ranks mpirun started in `session`."""
    pids = {}
    found = subprocess.run(["pgrep", "-s", str(session), "-x", "microbsdf"], capture_output=True, text=True)
    for pid in map(int, found.stdout.split()):
        try:
            env = open(f"/proc/{pid}/environ", "rb").read().split(b"\0")
        except OSError:
            continue
        for item in env:
            if item.startswith(b"OMPI_COMM_WORLD_RANK="):
                pids[int(item.split(b"=")[1])] = pid
    return pids


def test_silent_rank():
    """A worker that goes silent with a tile (SIGSTOP: to rank 0 a hung process, a frozen node and a
    cut link look alike) ends the run after --rank-timeout with exit 6, a message naming the rank, the
    slices safe in the partial file and --resume; --resume completes a table identical to a clean run.
    (Before, rank 0 waited for the tile until Open MPI noticed, or forever: a stopped process keeps its
    sockets.) Bounded waits only: the stop is observed, not timed."""
    job = many_tiles_job(os.path.join(TMP, "job.toml"), 12, "out.h5", paths=40000)
    run(["run", job, "-o", "ref.h5"])
    p = start(["run", job, "-o", "out.h5", "--rank-timeout", "10"], mpi=2)
    t0 = time.time()
    while journal_count(os.path.join(TMP, "out.h5")) < 2:
        assert p.poll() is None, "the run ended before the stop:\n" + p.stdout.read()
        assert time.time() - t0 < 300, "no slice finished"
        time.sleep(0.02)
    worker = rank_pids(p.pid)[1]
    os.kill(worker, signal.SIGSTOP)
    try:
        out, _ = p.communicate(timeout=300)
    finally:
        subprocess.run(["pkill", "-KILL", "-s", str(p.pid)])
        wait_session_gone(p.pid)
    assert p.returncode == 6, f"exit {p.returncode}, expected 6:\n{out}"
    print(next(line for line in out.splitlines() if "sent nothing" in line))
    for phrase in ("rank 1 sent nothing for", "--rank-timeout 10", "slices are safe in out.h5.partial", "--resume"):
        assert phrase in out, f"'{phrase}' not in the output:\n{out}"
    kept = journal_count(os.path.join(TMP, "out.h5"))
    text = expect(["run", job, "-o", "out.h5", "--resume"], 0, f"resuming: {kept} of 48 slices", mpi=2)
    assert datasets(os.path.join(TMP, "out.h5")) == datasets(os.path.join(TMP, "ref.h5")), "the resumed table differs"
    print(f"rank 1 stopped with a tile: exit 6 after {time.time() - t0:.0f} s naming it; {kept} slices kept, "
          "--resume identical to a clean run")
    # A live rank whose tiles each take longer than the timeout is not taken for a silent one: its
    # heartbeat does not wait for the tile's progress callbacks.
    slow = many_tiles_job(os.path.join(TMP, "slow.toml"), 1, "slow.h5", paths=5000000)
    t1 = time.time()
    text = expect(["run", slow, "-o", "slow.h5", "--rank-timeout", "2", "--threads", "1", "-v"], 0, mpi=2)
    tiles = [float(x) for x in re.findall(r"tile \d+: ([0-9.]+) s \(path tracing", text)]
    print(f"tiles of {min(tiles):.1f}-{max(tiles):.1f} s under --rank-timeout 2: completed ({time.time() - t1:.0f} s)")
    assert max(tiles) > 2, f"the tiles took {tiles} s: not longer than the timeout"


def test_damaged_tables():
    """Readers do not trust what they read: a foreign HDF5 file, a table without /bsdf/done or its
    grid's attributes, a finished table with one NaN, and a path-traced table with one negative value
    end `info`, `eval`, `diff`, `export` and `slice` with exit 2 naming the file (no HDF5 error
    stack; the NaN and negative ones name the dataset and slice), where they printed "L1 nan %", nan
    rows with exit 0, or exit 1; `info` reads every value of a file this small and says so."""
    job = small_job(os.path.join(TMP, "job.toml"), output="good.h5")
    run(["run", job, "-o", "good.h5"])
    with h5py.File(os.path.join(TMP, "foreign.h5"), "w") as h:
        h["data"] = np.arange(4.0)
    for name, edit in (("nodone", lambda h: h.__delitem__("/bsdf/done")),
                       ("nogrid", lambda h: h["/grid"].attrs.__delitem__("n_theta")),
                       ("nan", lambda h: h["/bsdf/coherent"].__setitem__((1, 0, 7), np.nan)),
                       ("negative", lambda h: h["/bsdf/multiple"].__setitem__((1, 0, 9), -0.5))):
        shutil.copy(os.path.join(TMP, "good.h5"), os.path.join(TMP, f"{name}.h5"))
        with h5py.File(os.path.join(TMP, f"{name}.h5"), "r+") as h:
            edit(h)
    readers = {"eval": lambda f: ["eval", f, "--wi", "20,10", "--wo", "20,190"], "diff": lambda f: ["diff", f, "good.h5"],
               "export": lambda f: ["export", f, "--format", "rgl", "-o", "x.bsdf"],
               "slice": lambda f: ["slice", f, "--theta-i", "20", "-o", "x.png"], "info": lambda f: ["info", f]}
    for name, phrase in (("foreign", "not a microbsdf output file"), ("nodone", "it has no /bsdf/done"),
                         ("nogrid", "a damaged microbsdf output file"), ("nan", "/bsdf/coherent of slice 1 holds nan"),
                         ("negative", "/bsdf/multiple of slice 1 holds -0.5")):
        for reader, args in readers.items():
            if name in ("nan", "negative") and reader == "export":
                continue  # export refuses this job's listed incidences before it reads a table
            text = expect(args(f"{name}.h5"), EXIT_BAD_INPUT, f"{name}.h5", phrase)
            assert "HDF5-DIAG" not in text, text
    assert "values: " in run(["info", "good.h5"]).stdout
    print("foreign, incomplete-schema, NaN and negative tables: every reader exits 2 naming the file")


FOLDER_FSYNC_SHIM = r"""
#define _GNU_SOURCE
#include <dlfcn.h>
#include <errno.h>
#include <stdlib.h>
#include <sys/stat.h>
#include <unistd.h>
/* fsync of a folder fails with EIO once the file named by FAIL_FOLDER_FSYNC_AFTER exists. */
int fsync(int fd) {
  static int (*real)(int);
  if (!real) real = (int (*)(int))dlsym(RTLD_NEXT, "fsync");
  struct stat st;
  const char *after = getenv("FAIL_FOLDER_FSYNC_AFTER");
  if (after && access(after, F_OK) == 0 && fstat(fd, &st) == 0 && S_ISDIR(st.st_mode)) {
    errno = EIO;
    return -1;
  }
  return real(fd);
}
"""


def test_folder_sync_after_rename():
    """EIO on the folder's fsync after the partial file was renamed to the output: exit 4 with a
    message that says what is true (the output complete and in place, its rename not yet durable),
    no journal left; it said "5/5 slices are safe in OUT.h5.partial ... OUT.h5 was not changed"
    while the partial was gone and the output replaced (fsync failed by an LD_PRELOAD shim)."""
    shim = os.path.join(TMP, "shim.so")
    with open(os.path.join(TMP, "shim.c"), "w") as f:
        f.write(FOLDER_FSYNC_SHIM)
    subprocess.run(["cc", "-shared", "-fPIC", "-o", shim, os.path.join(TMP, "shim.c"), "-ldl"], check=True)
    job = small_job(os.path.join(TMP, "job.toml"), output="c.h5")
    out = os.path.join(TMP, "c.h5")
    env = dict(ENV, LD_PRELOAD=shim, FAIL_FOLDER_FSYNC_AFTER=out)
    p = subprocess.run([EXE, "run", job, "-o", "c.h5"], capture_output=True, text=True, timeout=300, env=env, cwd=TMP)
    text = p.stdout + p.stderr
    assert p.returncode == EXIT_WRITE_FAILED, f"exit {p.returncode}:\n{text}"
    assert "is complete and in place" in text and "Input/output error" in text, text
    assert "was not changed" not in text and "safe in c.h5.partial" not in text, text
    assert not os.path.exists(out + ".journal") and not os.path.exists(out + ".partial")
    assert "complete:    5/5 slices" in run(["info", "c.h5"]).stdout
    print("EIO on the folder's fsync after the rename: exit 4 saying the output is complete and in place, no journal left")


def test_resume_finished():
    """--resume of an output this job already finished computes nothing (0 tiles, exit 0, the file
    byte-identical, under mpirun -np 2 too); the same with a changed job runs it afresh."""
    job = small_job(os.path.join(TMP, "job.toml"), output="out.h5")
    ref = good_output("out.h5", job)
    text = expect(["run", job, "-o", "out.h5", "--resume"], 0, "already a finished table of this job", mpi=2)
    assert "tiles computed now" not in text, text
    assert sha(os.path.join(TMP, "out.h5")) == ref, "a finished output was rewritten"
    with open(job) as f:
        changed = f.read().replace("seed = 7", "seed = 8")
    with open(job, "w") as f:
        f.write(changed)
    text = expect(["run", job, "-o", "out.h5", "--resume"], 0, "5 tiles computed now")
    assert "already a finished table" not in text and sha(os.path.join(TMP, "out.h5")) != ref, text
    print("--resume of a finished output: nothing computed, byte-identical (2 ranks); with a changed job: computed "
          "afresh")


def test_two_writers():
    """A second run on an output that a run is writing exits at once (5) naming the holder; the
    lock of a killed run is taken over; the good output is untouched until the first run ends."""
    ref = good_output("out.h5")
    job = many_tiles_job(os.path.join(TMP, "slow.toml"), 30, "out.h5", paths=200000)
    p = start(["run", job, "-o", "out.h5"], mpi=2)
    try:
        while journal_count(os.path.join(TMP, "out.h5")) < 1:
            assert p.poll() is None, p.communicate()[0]
            time.sleep(0.02)
        # Frozen, the run holds its lock however long the second runs take.
        os.killpg(p.pid, signal.SIGSTOP)
        t0 = time.time()
        text = expect(["run", job, "-o", "out.h5"], EXIT_BUSY, "is being written by another run", "PID")
        seconds = time.time() - t0
        assert sha(os.path.join(TMP, "out.h5")) == ref
        expect(["run", job, "-o", "out.h5", "--resume"], EXIT_BUSY, "is being written by another run", mpi=2)
    finally:
        os.killpg(p.pid, signal.SIGKILL)
        p.wait()
        wait_session_gone(p.pid)
    assert sha(os.path.join(TMP, "out.h5")) == ref
    # The killed run's lock is free (flock dies with its process): the next run notes and takes it.
    r = run(["run", job, "-o", "out.h5", "--resume", "--max-hours", "0.0001"], expect=None)
    assert r.returncode in (0, EXIT_STOPPED), r.stdout + r.stderr
    assert "is gone; taken over" in r.stdout + r.stderr, r.stdout + r.stderr
    print(f"second writer refused in {seconds:.2f} s: {text.strip().splitlines()[-1][:160]}; stale lock taken over")


def test_resume_changed_inputs():
    """--resume refuses a partial file whose mesh, heightfield or NDF table changed (same job text),
    and a job text with only a comment changed, saying what differs; the partial file stays as it was."""
    def mesh(path, z):
        with open(path, "w") as f:
            f.write(f"v -1 -1 0\nv 1 -1 0\nv 1 1 {z}\nv -1 1 0\nf 1 2 3\nf 1 3 4\n")

    def ndf(path, d):
        with open(path, "w") as f:
            f.write(f"0, 1\n30, {d}\n60, 0.1\n90, 0\n")

    def exr(path, theta):
        run(["slice", "good.h5", "--theta-i", str(theta), "--model", "GM", "--size", "16", "-o", path])

    good_output("good.h5")
    cases = {
        "mesh": ('kind = "mesh"\nfile = "patch.obj"', "patch.obj", lambda: mesh("patch.obj", 0.0),
                 lambda: mesh("patch.obj", 0.001)),
        "heightfield": ('kind = "heightfield"\nfile = "h.exr"\ntexel_um = 0.5', "h.exr", lambda: exr("h.exr", 0),
                        lambda: exr("h.exr", 20)),
        "ndf table": ('kind = "statistical"\nndf = "tabulated"\nndf_file = "ndf.txt"', "ndf.txt",
                      lambda: ndf("ndf.txt", 0.5), lambda: ndf("ndf.txt", 0.6)),
    }
    os.chdir(TMP)
    for name, (geometry, file, before, after) in cases.items():
        before()
        job = many_tiles_job(os.path.join(TMP, "r.toml"), 30, "r.h5", paths=100000)
        with open(job) as f:
            text = f.read()
        text = text[:text.index("[geometry]")] + "[geometry]\n" + geometry + "\n" + text[text.index("[material]"):]
        if name == "ndf table":
            text = text.replace('components = ["coherent", "incoherent", "multiple"]', 'components = ["coherent", "multiple"]')
        with open(job, "w") as f:
            f.write(text)
        killed_partial(job, "r.h5")
        partial = sha(os.path.join(TMP, "r.h5.partial"))
        after()
        expect(["run", job, "-o", "r.h5", "--resume"], EXIT_BAD_INPUT, "cannot resume", file,
               "changed since the partial file was written")
        assert sha(os.path.join(TMP, "r.h5.partial")) == partial, name
        before()  # restored: the resume goes on
        run(["run", job, "-o", "r.h5", "--resume"])
        for ext in ("", ".journal", ".partial"):
            if os.path.exists(os.path.join(TMP, "r.h5" + ext)):
                os.remove(os.path.join(TMP, "r.h5" + ext))
        print(f"{name}: a changed {file} refused with its name; restored, the resume completed")
    # A comment-only edit of the job text: refused, saying so.
    job = many_tiles_job(os.path.join(TMP, "c.toml"), 30, "c.h5", paths=100000)
    killed_partial(job, "c.h5")
    with open(job) as f:
        text = f.read()
    with open(job, "w") as f:
        f.write(text.replace("[material]", "# a note\n[material]"))
    expect(["run", job, "-o", "c.h5", "--resume"], EXIT_BAD_INPUT, "the job text differs from line",
           "only comments or white space differ")
    print("a comment-only edit: refused, naming the line and saying only comments differ")


def test_broken_meshes():
    """Malformed OBJ and PLY faces are errors naming file:line (or the face); a patch with a hole is
    reported by check, plan and the run log, and its light through the hole is `missed`; repeated faces
    are removed (the same tables); a second sheet over the first, or a face wound the other way round, is
    refused."""
    quad = "v -1 -1 0\nv 1 -1 0\nv 1 1 0\nv -1 1 0\n"
    files = {
        "trunc.obj": (quad + "f 1 2 3\nf 1\n", "trunc.obj:6", "a face needs at least 3 vertices"),
        "badidx.obj": (quad + "f 1 2 3\nf 1 3 9\n", "badidx.obj:6", "does not exist"),
        "badv.obj": ("v 1 2\n" + quad + "f 2 3 4\n", "badv.obj:1", "a vertex needs x y z"),
        "word.obj": (quad + "f 1 2 3\nf 1 3 x\n", "word.obj:6", "is not a vertex index"),
        "trunc.ply": ("ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\n"
                      "property float z\nelement face 2\nproperty list uchar int vertex_indices\nend_header\n"
                      "-1 -1 0\n1 -1 0\n1 1 0\n-1 1 0\n3 0 1 2\n1 0\n", "trunc.ply: face 1", "at least 3"),
    }
    for name, (content, where, what) in files.items():
        with open(os.path.join(TMP, name), "w") as f:
            f.write(content)
        job = small_job(os.path.join(TMP, name + ".toml"), geometry=f'kind = "mesh"\nfile = "{name}"')
        expect(["check", job], EXIT_BAD_INPUT, where, what)
        expect(["run", job, "-o", "broken.h5"], EXIT_BAD_INPUT, where, what)
        assert not os.path.exists(os.path.join(TMP, "broken.h5.partial"))
    # A stray vertex no face uses does not enlarge the footprint.
    with open(os.path.join(TMP, "stray.obj"), "w") as f:
        f.write(quad + "v 5 5 5 5\nf 1 2 3\nf 1 3 4\n")
    job = small_job(os.path.join(TMP, "stray.toml"), geometry='kind = "mesh"\nfile = "stray.obj"')
    out = expect(["check", job], 0, "2.000000 x 2.000000", "1 vertices used by no triangle")
    # A hole over half the patch: reported everywhere, and half the light is missed by every path.
    with open(os.path.join(TMP, "hole.obj"), "w") as f:
        f.write(quad + "f 1 2 3\n")
    job = small_job(os.path.join(TMP, "hole.toml"), geometry='kind = "mesh"\nfile = "hole.obj"',
                    extra='[effects]\ncomponents = ["coherent"]\n')
    expect(["check", job], 0, "open edges", "50 % of the footprint uncovered")
    plan = expect(["plan", job], 0, "50 % of the footprint uncovered")
    log = expect(["run", job, "-o", "hole.h5"], 0, "50 % of the footprint uncovered")
    info = json.loads(run(["info", "hole.h5", "--json"]).stdout)
    missed = np.array([s["missed"][0] for s in info["slices"]])
    # Binomial: 20 000 paths, p = 1/2; the facet sum (which assumes a closed surface) is not used.
    assert np.all(np.abs(missed - 0.5) < 4 * np.sqrt(0.25 / 20000)), missed
    facets = small_job(os.path.join(TMP, "hf.toml"), geometry='kind = "mesh"\nfile = "hole.obj"',
                       extra='[effects]\ncomponents = ["coherent"]\n')
    with open(facets) as f:
        text = f.read()
    with open(facets, "w") as f:
        f.write(text.replace("[sampling]\n", '[sampling]\nsingle_scattering = "facets"\n'))
    expect(["check", facets], EXIT_BAD_INPUT, "single_scattering", "needs a closed surface")
    # A face repeated by the exporter (again, and rotated with the other winding) would scatter twice:
    # removed with a warning, and the tables are those of the mesh without the repeats. A second sheet
    # over the first covers the footprint twice: refused, naming the file's key.
    tables = {}
    for name, faces in (("once.obj", "f 1 2 3\nf 1 3 4\n"), ("repeated.obj", "f 1 2 3\nf 1 3 4\nf 1 2 3\nf 3 2 1\n")):
        with open(os.path.join(TMP, name), "w") as f:
            f.write(quad + faces)
        job = small_job(os.path.join(TMP, name + ".toml"), geometry=f'kind = "mesh"\nfile = "{name}"',
                        extra='[effects]\ncomponents = ["coherent", "incoherent"]\n')
        log = expect(["run", job, "-o", name + ".h5"], 0, *(["removed 2 repeated triangles"] if name == "repeated.obj" else []))
        tables[name] = datasets(os.path.join(TMP, name + ".h5"))
    assert tables["once.obj"] == tables["repeated.obj"]
    with open(os.path.join(TMP, "sheets.obj"), "w") as f:
        f.write(quad + "v -1 -1 1\nv 1 -1 1\nv 1 1 1\nv -1 1 1\nf 1 2 3\nf 1 3 4\nf 5 6 7\nf 5 7 8\n")
    job = small_job(os.path.join(TMP, "sheets.toml"), geometry='kind = "mesh"\nfile = "sheets.obj"')
    expect(["check", job], EXIT_BAD_INPUT, "geometry.file", "cover the footprint 2 times")
    expect(["run", job, "-o", "sheets.h5"], EXIT_BAD_INPUT, "geometry.file", "cover the footprint 2 times")
    assert not os.path.exists(os.path.join(TMP, "sheets.h5.partial"))
    # A face wound the other way round faces the lower medium: refused, not taken for a hole.
    with open(os.path.join(TMP, "turned.obj"), "w") as f:
        f.write(quad + "f 1 2 3\nf 1 4 3\n")
    job = small_job(os.path.join(TMP, "turned.toml"), geometry='kind = "mesh"\nfile = "turned.obj"')
    expect(["check", job], EXIT_BAD_INPUT, "geometry.file", "not wound consistently")
    del out, plan, log
    print(f"OBJ/PLY faults named file:line; stray vertex ignored; a half-open patch: reported by check, plan and "
          f"run, missed = {missed.round(4).tolist()} (0.5 expected); repeated faces removed (the same tables), a "
          f"second sheet and a turned face refused")


def test_readonly_folders():
    """Read-only output and log folders: exit 2 before any compute, no abort."""
    ro = os.path.join(TMP, "ro")
    if not mount_tmpfs(ro, "1m") or subprocess.run(["mount", "-o", "remount,ro", ro]).returncode != 0:
        sys.exit("FAIL: cannot mount a read-only tmpfs (the test needs root, as CI has)")
    try:
        ref = good_output("good.h5")
        job = small_job(os.path.join(TMP, "job.toml"))
        expect(["run", job, "-o", "ro/out.h5"], EXIT_BAD_INPUT, "output folder ro is not writable", "Read-only file system")
        expect(["run", job, "-o", "good.h5", "--log-dir", "ro/logs"], EXIT_BAD_INPUT, "log folder ro/logs")
        expect(["run", job, "-o", "ro/out.h5"], EXIT_BAD_INPUT, "not writable", mpi=2)
        assert sha(os.path.join(TMP, "good.h5")) == ref
    finally:
        subprocess.run(["umount", ro], capture_output=True)
    print("read-only output and log folders (a read-only tmpfs): exit 2 with the folder named, 1 and 2 ranks")


def test_output_is_folder():
    """An output path that is a folder fails before any compute (no pilot, no tile, no lock or partial
    file left), without MPI_ABORT. The job's components are "auto": a late check would show the
    effects planner's pilots in the log. The same for `check --slice-paths`."""
    os.makedirs(os.path.join(TMP, "adir"))
    job = small_job(os.path.join(TMP, "job.toml"), extra='[effects]\ncomponents = "auto"\n')
    for mpi in (0, 2):
        text = expect(["run", job, "-o", "adir"], EXIT_BAD_INPUT, "output adir is a folder", mpi=mpi)
        for phase in ("pilot", "tile", "effects planner"):
            assert phase not in text, f"'{phase}' ran before the output check:\n{text}"
        assert os.listdir(os.path.join(TMP, "adir")) == [], os.listdir(os.path.join(TMP, "adir"))
        assert not [f for f in os.listdir(TMP) if f.startswith("adir.")], os.listdir(TMP)
        print(f"output is a folder, {mpi or 1} rank(s): exit 2 before any pilot or tile")
    # `check --slice-paths` names the folder before it reads the job.
    expect(["check", job, "--slice-paths", "adir"], EXIT_BAD_INPUT, "output adir is a folder")
    assert os.listdir(os.path.join(TMP, "adir")) == [], os.listdir(os.path.join(TMP, "adir"))


def test_pilot_signal():
    """SIGINT while the effects planner's pilots run (the paper's HEMISPHERES at 75 x 300 bins: a
    diffraction pilot of minutes): exit 3 long before the pilot would end, nothing written; the
    answer time the program measures is printed."""
    job = os.path.join(TMP, "pilot.toml")
    with open(os.path.join(SRC, "jobs", "paper-resolution", "hemispheres.toml")) as f:
        text = f.read()
    with open(job, "w") as f:  # components = "auto" (the default): the planner's pilots run first
        f.write(text.replace('components = ["coherent", "incoherent", "multiple"]', ""))
    ref = good_output("p.h5")
    for mpi in (0, 2):
        cmd = ([shutil.which("mpirun"), "-np", "2", "--oversubscribe"] if mpi else []) + [EXE, "run", job, "-o", "p.h5"]
        p = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=MPI_ENV if mpi else ENV, cwd=TMP,
                             start_new_session=True)
        lines = []
        for line in p.stdout:
            lines.append(line)
            if "effects planner: diffraction pilot" in line:
                break
        # Ctrl-C reaches every process of the terminal's group; under mpirun, mpirun forwards SIGUSR1
        # (SIGINT to mpirun itself kills the job with Open MPI's own exit code, see README).
        if mpi:
            os.killpg(p.pid, signal.SIGUSR1)
        else:
            os.kill(p.pid, signal.SIGINT)
        rest, _ = p.communicate(timeout=PHASE_SECONDS)
        text = "".join(lines) + rest
        assert p.returncode == EXIT_STOPPED, f"exit {p.returncode}\n{text}"
        seconds = answered(text, "stop requested during the effects planner's pilots")
        assert sha(os.path.join(TMP, "p.h5")) == ref and not os.path.exists(os.path.join(TMP, "p.h5.partial"))
        print(f"{'SIGUSR1 to mpirun -np 2' if mpi else 'SIGINT'} during a diffraction pilot: exit 3, "
              f"answered {seconds:.3f} s after the signal")
    # `plan` answers too.
    p = subprocess.Popen([EXE, "plan", job], stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=ENV,
                         cwd=TMP)
    for line in p.stdout:
        if "pilot" in line:
            break
    p.send_signal(signal.SIGINT)
    rest, _ = p.communicate(timeout=PHASE_SECONDS)
    assert p.returncode == EXIT_STOPPED, (p.returncode, rest)
    print(f"plan: SIGINT during its pilots, exit 3, answered {answered(rest, 'stopped on request'):.3f} s after the signal")


def test_partial_readers():
    """info, slice, sheet, render and plot_lobes.py read a partial file while its run holds it open
    mid-write and after the run was killed; they say it is incomplete and never draw a missing slice as black."""
    job = many_tiles_job(os.path.join(TMP, "job.toml"), 30, "p.h5", paths=200000)
    p = start(["run", job, "-o", "p.h5"], mpi=2)
    partial = os.path.join(TMP, "p.h5.partial")

    def read_all(when):
        info = run(["info", "p.h5.partial"])
        assert re.search(r"incomplete:\s+\d+ of 120 slices", info.stdout), info.stdout
        j = json.loads(run(["info", "p.h5.partial", "--json"]).stdout)
        assert not j["complete"] and 0 < j["done_count"] < 120, j["done_count"]
        done = [s for s in j["slices"] if s["done"]][0]
        missing = [s for s in j["slices"] if not s["done"]][0]
        run(["slice", "p.h5.partial", "--theta-i", str(done["theta_deg"]), "--phi-i", str(done["phi_deg"]),
             "--model", "GM", "-o", "s.png"])
        r = run(["slice", "p.h5.partial", "--theta-i", str(missing["theta_deg"]), "--phi-i",
                 str(missing["phi_deg"]), "--model", "GM", "-o", "m.png"], expect=EXIT_BAD_INPUT)
        assert "not computed yet: incomplete" in r.stderr, r.stderr
        r = run(["sheet", "p.h5.partial", "--size", "32", "-o", "sheet.png"])
        assert "incomplete:" in r.stderr and "hatched" in r.stderr, r.stderr
        r = run(["render", "p.h5.partial", "--size", "32", "--spp", "4", "-o", "render.png"])
        assert "incomplete:" in r.stderr and "stands in" in r.stderr, r.stderr
        r = subprocess.run(["/usr/bin/python3", os.path.join(SRC, "scripts", "plot_lobes.py"), "p.h5.partial",
                            "-o", "lobes.png"], capture_output=True, text=True, timeout=120, cwd=TMP)
        assert r.returncode == 0 and "incomplete:" in r.stderr, r.stderr
        # The sheet's missing cells are hatched red, not black.
        with h5py.File(partial, "r", swmr=True) as f:
            n_done = int(f["bsdf/done"][()].sum())
        print(f"{when}: {n_done} of 120 slices; info, slice, sheet, render and plot_lobes.py read it")

    try:
        while journal_count(os.path.join(TMP, "p.h5")) < 2:
            assert p.poll() is None, p.communicate()[0]
            time.sleep(0.02)
        # Frozen with its file open, the run stays mid-write however long the readers take.
        os.killpg(p.pid, signal.SIGSTOP)
        read_all("while the run writes it (stopped with the file open)")
    finally:
        os.killpg(p.pid, signal.SIGKILL)
        p.wait()
        wait_session_gone(p.pid)
    read_all("after the run was killed")


def test_small_inputs():
    """Smaller input faults, each an exit 2 naming the key: a repeated wavelength, a texel finer than
    the generator's cell limit, negative --threads and --max-hours, a job too large for the memory."""
    job = small_job(os.path.join(TMP, "dup.toml"))
    with open(job) as f:
        text = f.read()
    with open(job, "w") as f:
        f.write(text.replace("wavelengths_nm = [450.0, 650.0]", "wavelengths_nm = [550.0, 550.0]"))
    expect(["check", job], EXIT_BAD_INPUT, "wavelengths_nm", "550 nm is listed twice")
    texel = small_job(os.path.join(TMP, "texel.toml"),
                      geometry='kind = "gaussian"\nsize_um = [200.0, 200.0]\ntexel_um = 0.05')
    expect(["check", texel], EXIT_BAD_INPUT, "texel_um", "at most 2048")
    good = small_job(os.path.join(TMP, "good.toml"))
    expect(["run", good, "--threads", "-2"], EXIT_BAD_INPUT, "--threads")
    expect(["run", good, "--max-hours", "-1"], EXIT_BAD_INPUT, "--max-hours")
    # The bin limit under a 4 GB address space: refused before anything is written.
    big = os.path.join(TMP, "big.toml")
    with open(big, "w") as f:
        f.write('[geometry]\nkind = "flat"\n[material]\nname = "Al"\n[spectrum]\nwavelengths_nm = [500.0]\n'
                '[directions]\nn_theta = 2500\nn_phi = 10000\nincidence = [[0.0, 0.0]]\n'
                '[effects]\ncomponents = ["coherent"]\n[sampling]\npaths_per_slice = 1000\n')
    limited = ["/bin/sh", "-c", f"ulimit -v 4000000 && exec {EXE} run big.toml -o big.h5"]
    r = subprocess.run(limited, capture_output=True, text=True, timeout=120, env=ENV, cwd=TMP)
    assert r.returncode == EXIT_BAD_INPUT and "GB of memory" in r.stderr, (r.returncode, r.stderr[-2000:])
    assert not os.path.exists(os.path.join(TMP, "big.h5.partial"))
    r = subprocess.run(["/bin/sh", "-c", f"ulimit -v 4000000 && exec {EXE} check big.toml"], capture_output=True,
                       text=True, timeout=120, env=ENV, cwd=TMP)
    assert r.returncode == EXIT_BAD_INPUT and "GB per rank" in r.stderr, (r.returncode, r.stderr)
    print("repeated wavelength, texel limit, negative --threads/--max-hours, memory: exit 2 naming each")


def test_derived_outputs():
    """What is made from a finished file (slices as PNG, EXR and CSV, a contact sheet, a preview as PNG
    and EXR, a report, an export, a diff image): onto a full disk each exits 4 naming the path,
    leaves an old file of that name byte-identical and no partial file behind; into a read-only
    folder or onto a folder, exit 2 naming it."""
    job = small_job(os.path.join(TMP, "job.toml"))
    with open(job) as f:  # angles x azimuths, as the Zemax format needs
        text = f.read().replace("incidence = [[0.0, 0.0], [20.0, 10.0], [45.0, 90.0], [70.0, 200.0], [85.0, 300.0]]",
                                "incidence = [[0.0, 0.0], [30.0, 0.0], [60.0, 0.0]]")
    with open(job, "w") as f:
        f.write(text)
    run(["run", job, "-o", "t.h5"])
    small = ["--size", "16"]
    makers = {
        "slice.png": ["slice", "t.h5"] + small,
        "slice.exr": ["slice", "t.h5"] + small,
        "slice.csv": ["slice", "t.h5"],
        "sheet.png": ["sheet", "t.h5"] + small,
        "preview.png": ["render", "t.h5", "--spp", "1"] + small,
        "preview.exr": ["render", "t.h5", "--spp", "1"] + small,
        "report.html": ["report", "t.h5"],
        "table.bsdf": ["export", "t.h5", "--lambda-nm", "450"],
        "diff.png": ["diff", "t.h5", "t.h5"],
    }
    # Each made once where there is room: the old file the full disk must not damage.
    for name, args in makers.items():
        run(args + ["-o", name])
    disk, ro = os.path.join(TMP, "disk"), os.path.join(TMP, "ro")
    if not mount_tmpfs(disk, "8m"):
        sys.exit("FAIL: cannot mount a tmpfs (the test needs root, as CI has)")
    if not mount_tmpfs(ro, "1m") or subprocess.run(["mount", "-o", "remount,ro", ro]).returncode != 0:
        subprocess.run(["umount", disk], capture_output=True)
        sys.exit("FAIL: cannot mount a read-only tmpfs (the test needs root, as CI has)")
    try:
        for name in makers:
            shutil.copy(os.path.join(TMP, name), os.path.join(disk, name))
        subprocess.run(["dd", "if=/dev/zero", f"of={disk}/filler", "bs=4k"], capture_output=True)
        os.makedirs(os.path.join(TMP, "folder.png"))
        for name, args in makers.items():
            old = sha(os.path.join(disk, name))
            expect(args + ["-o", "disk/" + name], EXIT_WRITE_FAILED, "disk/" + name)
            assert sha(os.path.join(disk, name)) == old, f"{name}: the old file was damaged"
            assert not os.path.exists(os.path.join(disk, name + ".partial")), f"{name}: partial file left"
            expect(args + ["-o", "ro/" + name], EXIT_BAD_INPUT, "ro")
            expect(args + ["-o", "folder.png"], EXIT_BAD_INPUT, "folder.png")
    finally:
        subprocess.run(["umount", disk], capture_output=True)
        subprocess.run(["umount", ro], capture_output=True)
    print(f"{len(makers)} derived outputs: a full disk exits 4 with the old file byte-identical and no partial "
          "file; a read-only folder or a folder as output exits 2")


def test_exit_codes_documented():
    """The README's exit-code table lists every code the program uses (core/error.h)."""
    with open(os.path.join(SRC, "src", "core", "error.h")) as f:
        codes = sorted({int(c) for c in re.findall(r"^\s+\w+ = (\d+),", f.read(), re.M)})
    with open(os.path.join(SRC, "README.md")) as f:
        readme = f.read()
    table = readme[readme.index("## Exit codes"):]
    for c in codes:
        assert re.search(rf"^\| `{c}` \|", table, re.M), f"exit code {c} is not in the README's table"
    print("README documents exit codes", codes)


run_selected(globals())
