#!/usr/bin/python3
"""Integration tests that run the microbsdf binary (single rank and under mpirun).

Usage: cli_test.py BUILD_DIR SOURCE_DIR TEST_NAME (see harness.py).
"""
import csv
import json
import re
import os
import signal
import subprocess
import sys
import time

import numpy as np

from harness import *  # noqa: F401,F403 (BUILD, SRC, EXE, ENV, TMP, run, small_job, datasets, ...)


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
    # One process with debug logging: the start-up breakdown names the memory allocator the program
    # was built with (jemalloc, huge pages only where the program asks for them), and each tile's
    # time is logged.
    p = run(["run", "quickstart.toml", "-o", "q1.h5", "-v"], timeout=600)
    text = p.stdout + p.stderr
    assert "memory allocator jemalloc (transparent huge pages: where the program asks" in text, text[-3000:]
    tiles = re.findall(r"tile (\d+): ([0-9.]+) s \(path tracing ([0-9.]+) s", text)
    assert sorted(int(t) for t, _, _ in tiles) == [0, 1, 2, 3], text[-3000:]
    # Its geometry is made from parameters: the job is always read while MPI starts. The tile
    # computer is built there too when the job was read before MPI was up, otherwise by the run on
    # all cores; which one happens depends on how fast MPI starts, so either is right, and the log
    # says which.
    assert re.search(r"job file and geometry [0-9.]+ s while MPI started", text), text[-3000:]
    early = re.search(r"the tile computer [0-9.]+ s while MPI started;", text)
    late = re.search(r"the tile computer \(scenes, facet tables, wave estimator\) [0-9.]+ s(, while MPI started)?",
                     text)
    assert late, text[-3000:]
    assert bool(early) == bool(late.group(1)), text[-3000:]
    # The table is the two ranks' to the byte.
    assert datasets(os.path.join(TMP, "q1.h5")) == datasets(os.path.join(TMP, "q.h5")), "1 process vs 2 ranks differ"
    print("quickstart: complete;", info["done_count"], "slices; one process:", ", ".join(f"tile {t} {s} s" for t, s, _ in tiles))


def test_determinism():
    job = small_job(os.path.join(TMP, "job.toml"))
    run(["run", job, "-o", "t1.h5", "--threads", "1"])
    run(["run", job, "-o", "t2.h5", "--threads", "2"])
    run(["run", job, "-o", "n2.h5", "--threads", "1"], mpi=2)
    run(["run", job, "-o", "n3.h5", "--threads", "1"], mpi=3)
    ref = datasets(os.path.join(TMP, "t1.h5"))
    for other in ("t2.h5", "n2.h5", "n3.h5"):
        assert datasets(os.path.join(TMP, other)) == ref, f"{other} differs from 1 rank x 1 thread"
    print("byte-identical datasets for 1 rank x 1 thread, 1 x 2, 2 x 1 and 3 x 1 (oversubscribed):", sorted(ref))


def test_statistical_job():
    """A statistical (microflake) surface through the same pipeline: mpirun -np 2, info, determinism."""
    geometry = 'kind = "statistical"\nndf = "ggx"\nalpha = [0.3, 0.6]\n'
    job = small_job(os.path.join(TMP, "stat.toml"), geometry=geometry)
    run(["run", job, "-o", "s1.h5", "--threads", "1"])
    run(["run", job, "-o", "s2.h5", "--threads", "1"], mpi=2)
    assert datasets(os.path.join(TMP, "s1.h5")) == datasets(os.path.join(TMP, "s2.h5")), "1 vs 2 ranks differ"
    info = json.loads(run(["info", "s2.h5", "--json"]).stdout)
    assert info["complete"] and info["geometry_kind"] == "statistical", info
    for s in info["slices"]:
        refl = s["energy"]["reflected"]
        gm = np.array(refl["coherent"]) + np.array(refl["multiple"])
        assert np.all(gm > 0.3) and np.all(gm < 1.0), gm  # gold at 450 and 650 nm
        assert np.all(np.array(refl["multiple"]) > 0), refl
    # Lobe and albedo plots from the file (scripts/plot_lobes.py).
    png = os.path.join(TMP, "lobes.png")
    subprocess.run([sys.executable, os.path.join(SRC, "scripts", "plot_lobes.py"), os.path.join(TMP, "s2.h5"), "-o", png,
                    "--theta-i", "0", "45", "85"], check=True, timeout=120)
    assert open(png, "rb").read(8) == b"\x89PNG\r\n\x1a\n"
    # The shipped examples parse.
    for name in ("rough-gold.toml", "chandrasekhar.toml"):
        run(["check", os.path.join(SRC, "jobs", "statistical", name)])
    # compare-smith: explicit Gaussian heightfield vs the Smith model, total albedo within 3 %.
    r = run(["compare-smith", "--alpha", "0.3", "--paths", "20000", "--theta", "0,60", "--size-um", "16",
             "--json", "cs.json"], timeout=300)
    res = json.load(open(os.path.join(TMP, "cs.json")))
    assert abs(res["mesh_alpha"] - 0.3) < 1e-9, res["mesh_alpha"]
    for row in res["rows"]:
        t = row["total"]
        assert abs(t["albedo_explicit"] / t["albedo_smith"] - 1) < 0.03, row
    print(r.stdout)
    print("statistical job: complete under 2 ranks, identical to 1 rank; mean albedos",
          [round(float(np.mean(np.array(s["energy"]["reflected"]["coherent"]) +
                               np.array(s["energy"]["reflected"]["multiple"]))), 4) for s in info["slices"]])


def test_progressive():
    """[sampling] target_rel_error: rounds of paths until the relative error of the slice's path-traced
    table (/stats/paths_rel_error) reaches the target or max_paths_per_slice is spent; recorded per
    slice; identical for 1 and 2 ranks."""
    job = small_job(os.path.join(TMP, "prog.toml"))
    text = open(job).read().replace("paths_per_slice = 20000",
                                    "paths_per_slice = 4000\ntarget_rel_error = 0.01\nmax_paths_per_slice = 40000")
    open(job, "w").write(text)
    run(["run", job, "-o", "p1.h5", "--threads", "1"])
    run(["run", job, "-o", "p2.h5"], mpi=2)
    assert datasets(os.path.join(TMP, "p1.h5")) == datasets(os.path.join(TMP, "p2.h5")), "1 vs 2 ranks differ"
    info = json.loads(run(["info", "p2.h5", "--json"]).stdout)
    stops = {}
    for s in info["slices"]:
        rel = max(s["paths_rel_error"])
        assert s["samples"] % 4000 == 0 and 4000 <= s["samples"] <= 40000, s["samples"]
        if s["sampling_stop"] == "target":
            assert rel <= 0.01, (rel, s)
            assert s["samples"] == 4000 or rel > 0.01 * 0.5, "stopped late"  # one round more would not be needed
        else:
            assert s["sampling_stop"] == "budget" and s["samples"] == 40000 and rel > 0.01, s
        stops[s["index"]] = (s["sampling_stop"], s["samples"], round(rel, 4))
    assert any(v[1] > 4000 for v in stops.values()), stops  # at least one slice needed more rounds
    text_info = run(["info", "p2.h5"]).stdout
    assert "progressive sampling:" in text_info, text_info
    print("progressive sampling (target 1 %, rounds of 4000 paths, budget 40000):", stops)


def reciprocity_job(path, material, output, extra="", scene=""):
    """A full-sphere WS job (incidence = "all") on a rough gaussian patch: the wave term is halved."""
    n_theta, n_phi = (4, 8) if "conductor" in material else (3, 6)
    with open(path, "w") as f:
        f.write(f"""[geometry]
kind = "gaussian"
size_um = [10.0, 10.0]
rms_um = 0.3
correlation_um = 1.0
[material]
{material}
[spectrum]
wavelengths_nm = [450.0, 650.0]
[directions]
n_theta = {n_theta}
n_phi = {n_phi}
incidence = "all"
[scene]
{scene}
[effects]
components = ["coherent", "incoherent"]
{extra}
[sampling]
paths_per_slice = 5000
wave_estimator = "area"
wave_samples_per_bin = 256
seed = 3
[output]
path = "{output}"
""")
    return path


def test_reciprocity():
    """[effects] reciprocity (default on) for a full-sphere job: the wave term is computed once per pair
    of same-side incidence bins and the mirrored half filled at the end; every other entry is the same
    bytes as a run that computes both halves, the mirrored ones are f_ws(o->i) - coherent(i->o) of that
    run, nothing is NaN, the per-slice energies match the rows, and the wave samples fall to the
    computed fraction of the pairs. The third job restricts the incidences to 60 degrees from the
    normal ([scene] incidence_max_deg): the exit bins beyond are computed by every tile."""
    dielectric = 'kind = "dielectric"\nior = 1.5'
    for name, material, scene in (("al", 'kind = "conductor"\nname = "Al"', ""), ("glass", dielectric, ""),
                                  ("glass-range", dielectric, "incidence_max_deg = 60")):
        on = reciprocity_job(os.path.join(TMP, f"{name}-on.toml"), material, f"{name}-on.h5", scene=scene)
        off = reciprocity_job(os.path.join(TMP, f"{name}-off.toml"), material, f"{name}-off.h5", "reciprocity = false",
                              scene=scene)
        r_on = run(["run", on], mpi=2)
        run(["run", off], mpi=2)
        run(["run", on, "-o", f"{name}-on1.h5", "--threads", "1"])
        assert datasets(os.path.join(TMP, f"{name}-on.h5")) == datasets(os.path.join(TMP, f"{name}-on1.h5")), \
            "1 rank and 2 ranks differ with reciprocity"
        assert "mirrored when every slice is done" in r_on.stderr + r_on.stdout
        with h5py.File(os.path.join(TMP, f"{name}-on.h5"), "r") as a, h5py.File(os.path.join(TMP, f"{name}-off.h5"), "r") as b:
            text = lambda v: v.decode() if isinstance(v, bytes) else str(v)  # noqa: E731
            assert text(a.attrs["reciprocity"]).startswith("wave term computed once"), a.attrs["reciprocity"]
            assert text(b.attrs["reciprocity"]).startswith("not used: [effects] reciprocity = false"), b.attrs["reciprocity"]
            inc = a["/incidence/bin"][:]
            nh = a["/grid/theta_deg"].shape[0] // 2
            if scene:
                theta = a["/incidence/theta_deg"][:]
                assert np.all(np.minimum(theta, 180 - theta) <= 60) and len(inc) == 24, (theta, len(inc))
            op = a["/grid/projected_solid_angle"][:]
            ia, ea, ib = a["/bsdf/incoherent"][:], a["/bsdf_stderr/incoherent"][:], b["/bsdf/incoherent"][:]
            eb = b["/bsdf_stderr/incoherent"][:]
            cb, ecb = b["/bsdf/coherent"][:], b["/bsdf_stderr/coherent"][:]
            assert np.array_equal(a["/bsdf/coherent"][:], cb)
            assert np.all(np.isfinite(ia)) and np.all(np.isfinite(ea)), "NaN left in the filled table"
            index_of = {int(bn): k for k, bn in enumerate(inc)}
            up = lambda bn: bn < nh  # noqa: E731
            side = {True: [k for k, bn in enumerate(inc) if up(bn)], False: [k for k, bn in enumerate(inc) if not up(bn)]}
            own = mirrored = 0
            for i, bi in enumerate(inc):
                group = side[up(bi)]
                for o in range(ia.shape[2]):
                    j = index_of.get(o)
                    if j is None or j == i or up(o) != up(bi):
                        mine = True
                    else:
                        n = len(group)
                        d = (group.index(j) - group.index(i)) % n
                        mine = 2 * d < n or (2 * d == n and i < j)
                    if mine:
                        assert np.array_equal(ia[i, :, o], ib[i, :, o]) and np.array_equal(ea[i, :, o], eb[i, :, o]), (i, o)
                        own += 1
                    else:
                        # The other run's f_ws(j -> bin i) = incoherent + coherent of row j.
                        fws = ib[j, :, bi].astype(float) + cb[j, :, bi]
                        expect = fws - cb[i, :, o]
                        # Rounded to its noise as every stored value (docs/output.md): within σ/32, its
                        # error within 2^-8 (of errors themselves rounded so).
                        noise = ea[i, :, o].astype(float) / 32 * (1 + 2.0 ** -7)
                        assert np.all(np.abs(ia[i, :, o] - expect) <= noise + 1e-5 * np.abs(expect) + 1e-6), \
                            (i, o, ia[i, :, o], expect, noise)
                        var_ws = np.maximum(eb[j, :, bi].astype(float) ** 2 - ecb[j, :, bi].astype(float) ** 2, 0)
                        assert np.allclose(ea[i, :, o], np.sqrt(var_ws + ecb[i, :, o].astype(float) ** 2),
                                           rtol=3 * 2.0 ** -8, atol=1e-6)
                        mirrored += 1
            # The per-slice energies are those of the filled rows.
            refl = (ia * np.where(np.arange(len(op)) < nh, op, 0)).sum(axis=2)
            assert np.allclose(a["/stats/energy_reflected/incoherent"][:, :, 0], refl, rtol=1e-5, atol=1e-6)
            ws_on, ws_off = a["/stats/wave_samples"][:].sum(), b["/stats/wave_samples"][:].sum()
            n_up, n_down = len(side[True]), len(side[False])
            pairs = sum(n + n * (n - 1) // 2 for n in (n_up, n_down))
            exits = (n_up + n_down) * (2 * nh if n_down else nh)  # a dielectric's tiles estimate both hemispheres
            expected = (exits - sum(n * n for n in (n_up, n_down)) + pairs) / exits
            assert abs(ws_on / ws_off - expected) < 1e-12, (ws_on, ws_off, expected)
        info = json.loads(run(["info", f"{name}-on.h5", "--json"]).stdout)
        assert info["complete"] and info["reciprocity"].startswith("wave term computed once")
        plan = run(["plan", on]).stdout
        assert "reciprocity:    wave term for" in plan, plan
        print(f"{name}: {own} entries identical to the full run, {mirrored} mirrored (f_ws(o->i) - coherent(i->o)); "
              f"wave samples {ws_on} vs {ws_off} ({ws_on / ws_off:.3f} = expected {expected:.3f}); 1 and 2 ranks identical")


def test_storage_profiles():
    """[output] profile = "compact" against the full profile of the same job (same seeds): every table
    value equal to the full file's within half precision's rounding (read through python/microbsdf_h5.py,
    the helper for h5py users), the per-slice statistics identical, no per-bin error tables, 1 and 2
    ranks byte-identical, `info` naming the profile, and `plan`'s projected bytes per slice within 10 %
    of what each file stores per slice. Then the reciprocity fill of a halved wave term in float16:
    the filled table equal to the float32 run's within the same rounding."""
    sys.path.insert(0, os.path.join(SRC, "python"))
    import microbsdf_h5 as mh  # noqa: E402

    half_ulp = 2.0 ** -11 + 2.0 ** -23  # rounded through float to half, to nearest

    def close_in_half(x, y, what):
        peak = np.nanmax(np.abs(y), axis=-1, keepdims=True)
        bound = half_ulp * np.abs(y) + peak * 2.0 ** -39  # the scaled subnormal step below 2^-29 of the peak
        assert np.all(np.isfinite(x) == np.isfinite(y)), what
        bad = np.abs(x - y) > bound
        assert not np.any(bad[np.isfinite(y)]), (what, np.argwhere(bad)[:5])

    def stored_per_slice(path):
        with h5py.File(os.path.join(TMP, path), "r") as f:
            total = 0

            def visit(name, obj):
                nonlocal total
                if isinstance(obj, h5py.Dataset) and name.split("/")[0] in ("bsdf", "bsdf_stderr", "bsdf_scale",
                                                                                "bsdf_stderr_scale", "stats"):
                    total += obj.id.get_storage_size()
            f.visititems(visit)
            return total / f["/bsdf/done"].shape[0]

    src = open(os.path.join(SRC, "jobs", "quickstart.toml")).read()
    full = os.path.join(TMP, "full.toml")
    compact = os.path.join(TMP, "compact.toml")
    open(full, "w").write(src)
    open(compact, "w").write(src.replace("[output]", '[output]\nprofile = "compact"'))
    run(["run", full, "-o", "full.h5"])
    run(["run", compact, "-o", "compact.h5"])
    run(["run", compact, "-o", "compact2.h5", "--threads", "1"], mpi=2)
    assert datasets(os.path.join(TMP, "compact.h5")) == datasets(os.path.join(TMP, "compact2.h5")), "1 vs 2 ranks"
    with h5py.File(os.path.join(TMP, "compact.h5"), "r") as c, h5py.File(os.path.join(TMP, "full.h5"), "r") as f:
        assert "bsdf_stderr" not in c and c["/bsdf/coherent"].dtype == np.float16
        assert mh.storage_profile(c).startswith("compact") and mh.storage_profile(f).startswith("full")
        for comp in ("coherent", "multiple"):
            close_in_half(mh.table(c, comp), mh.table(f, comp), comp)
            assert np.array_equal(c[f"/stats/energy_reflected/{comp}"][:], f[f"/stats/energy_reflected/{comp}"][:])
            assert np.array_equal(c[f"/stats/rel_error/{comp}"][:], f[f"/stats/rel_error/{comp}"][:])
            assert not mh.has_bin_errors(c, comp) and mh.has_bin_errors(f, comp)
    assert "storage:     compact" in run(["info", "compact.h5"]).stdout
    # Every reader of the program reads the compact file: slice (its CSV without per-bin errors),
    # render (and export, below).
    run(["slice", "compact.h5", "--model", "GM", "-o", "compact.csv"])
    header = open(os.path.join(TMP, "compact.csv")).read().split("\n")[:2]
    assert "per slice" in header[0] and "stderr" not in header[1], header
    run(["render", "compact.h5", "-o", "compact.png"])
    sizes = {}
    for job, out in ((full, "full.h5"), (compact, "compact.h5")):
        run(["plan", job, "--json", out + ".plan.json"])
        plan = json.load(open(os.path.join(TMP, out + ".plan.json")))
        predicted, stored = plan["output"]["bytes_per_slice"], stored_per_slice(out)
        sizes[out] = (predicted, stored)
        assert abs(predicted / stored - 1) <= 0.10, (out, predicted, stored)
    assert sizes["compact.h5"][1] <= 0.5 * sizes["full.h5"][1], sizes
    # The reciprocity fill in float16.
    material = 'kind = "conductor"\nname = "Al"'
    on = reciprocity_job(os.path.join(TMP, "rc-on.toml"), material, "rc-on.h5")
    # (Both unrounded: the filled values are sums of stored ones, which rounding to the noise would
    # round again from inputs that differ by half's rounding.)
    half, exact = os.path.join(TMP, "rc-half.toml"), os.path.join(TMP, "rc-exact.toml")
    open(half, "w").write(open(on).read().replace("[output]", '[output]\nvalues = "float16"\nrounding = "none"').replace(
        "rc-on.h5", "rc-half.h5"))
    open(exact, "w").write(open(on).read().replace("[output]", '[output]\nrounding = "none"').replace(
        "rc-on.h5", "rc-exact.h5"))
    run(["run", on], mpi=2)
    run(["run", exact], mpi=2)
    run(["run", half], mpi=2)
    with h5py.File(os.path.join(TMP, "rc-half.h5"), "r") as h, h5py.File(os.path.join(TMP, "rc-exact.h5"), "r") as f:
        inc_bins = h["/incidence/bin"][:]
        index_of = {int(b): k for k, b in enumerate(inc_bins)}
        for err in (False, True):
            close_in_half(mh.table(h, "coherent", err), mh.table(f, "coherent", err), ("coherent", err))
            x, y = mh.table(h, "incoherent", err), mh.table(f, "incoherent", err)
            ci, cf = mh.table(h, "coherent", err), mh.table(f, "incoherent", err)
            assert np.all(np.isfinite(x)), "NaN left in the filled float16 table"
            # A mirrored entry (i, o) is inc(j -> bin i) + coh(j -> bin i) - coh(i -> o) of stored values
            # (for the errors, their quadrature): each rounded once to half, the result once more.
            bound = half_ulp * np.abs(y) + np.nanmax(np.abs(y), axis=-1, keepdims=True) * 2.0 ** -39
            for i, bi in enumerate(inc_bins):
                for o, j in index_of.items():
                    terms = np.abs(cf[j, :, bi]) + np.abs(ci[j, :, bi]) + np.abs(ci[i, :, o]) + np.abs(y[i, :, o])
                    peaks = np.max(np.abs(cf[j]), axis=-1) + np.max(np.abs(ci[j]), axis=-1) + np.max(np.abs(ci[i]), axis=-1)
                    bound[i, :, o] = np.maximum(bound[i, :, o], 2 * half_ulp * terms + peaks * 2.0 ** -38)
            assert np.all(np.abs(x - y) <= bound), ("incoherent", err, np.max(np.abs(x - y) / bound))
    run(["export", "rc-half.h5", "--format", "rgl", "--model", "WS", "-o", "rc-half.bsdf"])
    # Colour: quickstart at 8 wavelengths, compact (XYZ) against full: each channel is the full
    # table's spectrum through /colour/weights, to half precision; the statistics stay spectral.
    eight = src.replace("wavelengths_nm = [450.0, 550.0, 650.0]", "wavelengths_nm = { min = 400.0, max = 700.0, count = 8 }")
    assert eight != src
    # (Both unrounded: the colour of a spectrum, not of its rounding to the noise, is checked.)
    open(os.path.join(TMP, "full8.toml"), "w").write(eight.replace("[output]", '[output]\nrounding = "none"'))
    open(os.path.join(TMP, "compact8.toml"), "w").write(
        eight.replace("[output]", '[output]\nprofile = "compact"\nrounding = "none"'))
    run(["run", "full8.toml", "-o", "full8.h5"])
    run(["run", "compact8.toml", "-o", "compact8.h5"])
    with h5py.File(os.path.join(TMP, "compact8.h5"), "r") as c, h5py.File(os.path.join(TMP, "full8.h5"), "r") as f:
        assert mh.channels(c) == ["X", "Y", "Z"] and len(mh.channels(f)) == 8
        w = c["/colour/weights"][:]
        for comp in ("coherent", "multiple"):
            xyz = np.einsum("ilb,lc->icb", mh.table(f, comp), w)  # float32 spectra: their own rounding
            rel = np.abs(mh.table(c, comp) - xyz) / np.maximum(np.abs(xyz), 1e-300)
            assert np.all((rel <= half_ulp + 8 * 2.0 ** -24) | (np.abs(xyz) < 2.0 ** -20 * np.max(np.abs(xyz)))), comp
            assert np.array_equal(c[f"/stats/energy_reflected/{comp}"][:], f[f"/stats/energy_reflected/{comp}"][:])
    open(os.path.join(TMP, "compact8-noise.toml"), "w").write(eight.replace("[output]", '[output]\nprofile = "compact"'))
    run(["run", "compact8-noise.toml", "-o", "compact8-noise.h5"])
    colour_size = stored_per_slice("compact8-noise.h5")
    # Exports of a colour table (incidence = "all": the reciprocity job, whose halving the colour turns off).
    xyz_job = os.path.join(TMP, "rc-xyz.toml")
    open(xyz_job, "w").write(open(on).read().replace("[output]", '[output]\ncolour = "xyz"').replace("rc-on.h5", "rc-xyz.h5"))
    assert "not used: [output] colour" in run(["plan", xyz_job]).stdout
    run(["run", xyz_job], mpi=2)
    r = run(["export", "rc-xyz.h5", "--format", "rgl", "--model", "WS", "-o", "rc-xyz.bsdf"])
    assert "stores its tables in colour" in r.stderr, r.stderr
    run(["export", "rc-xyz.h5", "--format", "zemax", "--model", "WS", "-o", "rc-xyz.zmx.bsdf"])
    run(["export", "rc-xyz.h5", "--format", "mbsdf", "--model", "WS", "-o", "rc-xyz.mbsdf"])
    assert run(["export", "rc-xyz.h5", "--format", "zemax", "--lambda-nm", "450", "-o", "x.bsdf"], expect=2).returncode == 2
    print("compact vs full: every value within half precision, statistics identical; stored per slice "
          f"(plan / file): full {sizes['full.h5'][0]:.0f} / {sizes['full.h5'][1]:.0f} B, compact "
          f"{sizes['compact.h5'][0]:.0f} / {sizes['compact.h5'][1]:.0f} B; reciprocity fill in float16 as in float32; "
          f"8 wavelengths in XYZ {colour_size:.0f} B per slice")


def test_pairs_stored_once():
    """[output] pairs = "once" on a full-sphere job (rough gold, coherent + multiple, 2 ranks): every
    slice read back whole (C++ `slice`, and python/microbsdf_h5.py) equals the mean of both estimates
    of the same job stored both ways, f(i -> o) and f(o -> i), weighted by the projected solid angles
    of the bins each was tallied in; against a reference run with 16 times the paths (another seed)
    the stored table's z-scores have mean square 1 within the estimator's own spread, and its
    measured deviation from the reference falls by about sqrt(2) against a single estimate's; `plan`
    predicts each pilot slice's L1 within 5 % of what the stored errors give; the reciprocity check
    recorded in the file has mean z² about 1; the file is about half the size of the one storing
    both."""
    sys.path.insert(0, os.path.join(SRC, "python"))
    import microbsdf_h5 as mh  # noqa: E402

    job = full_sphere_job
    run(["run", job("both", 'pairs = "both"')], mpi=2)
    run(["run", job("once", 'pairs = "once"')], mpi=2)
    run(["run", job("once1", 'pairs = "once"'), "--threads", "1"])
    assert datasets(os.path.join(TMP, "once.h5")) == datasets(os.path.join(TMP, "once1.h5")), "1 vs 2 ranks"
    run(["run", job("ref", 'pairs = "both"', paths=320000, seed=7)], mpi=2)
    with h5py.File(os.path.join(TMP, "once.h5"), "r") as o, h5py.File(os.path.join(TMP, "both.h5"), "r") as b, \
            h5py.File(os.path.join(TMP, "ref.h5"), "r") as r:
        bins = b["/incidence/bin"][:].astype(int)
        n = len(bins)
        report = json.loads(o.attrs["pairs"].decode().split("check of each: ", 1)[1][:-1])
        for comp in ("coherent", "multiple"):
            fo, so = mh.table(o, comp), mh.table(o, comp, error=True)
            fb, sb = mh.table(b, comp), mh.table(b, comp, error=True)
            fr, sr = mh.table(r, comp), mh.table(r, comp, error=True)
            assert np.all(np.isfinite(fo)) and np.all(np.isfinite(so))
            raw = o[f"/bsdf/{comp}"][:]
            assert np.isnan(raw).sum() == n * (n - 1) // 2 * raw.shape[1], "the mirrored half is not stored"
            # The mean of both estimates, bin by bin, each weighted by the projected solid angle of the
            # bin it was tallied in.
            mean = fb.copy()
            pair = fb[:, :, bins]  # (i, row, j) = f(i -> bin j)
            op = b["/grid/projected_solid_angle"][:][bins]
            w = op[None, None, :] / (op[None, None, :] + op[:, None, None])  # of f(i -> bin j)
            mean[:, :, bins] = w * pair + (1 - w) * np.transpose(pair, (2, 1, 0))
            # (each rounded to its noise: the mean to σ/32 of the error stored with it)
            assert np.all(np.abs(fo - mean) <= so / 32 * (1 + 2.0 ** -7) + 1e-6 * np.abs(mean) + 1e-12), comp
            for i in (0, n // 2, n - 1):
                assert np.allclose(mh.slice(o, comp, i), fo[i], rtol=1e-12, atol=0), (comp, i)
            # Against the reference: z-scores of the stored table and of a single estimate.
            sel = np.zeros(fb.shape, bool)
            sel[:, :, bins] = True
            for i in range(n):
                sel[i, :, bins[i]] = False  # the diagonal is one estimate either way
            sel &= (sb > 0) & (sr > 0)
            z_once = ((fo - fr) / np.sqrt(so ** 2 + sr ** 2))[sel]
            z_both = ((fb - fr) / np.sqrt(sb ** 2 + sr ** 2))[sel]
            spread = 5 * np.sqrt(2.0 / sel.sum())
            assert abs(np.mean(z_once ** 2) - 1) < spread + 0.1, (comp, np.mean(z_once ** 2), sel.sum())
            assert abs(np.mean(z_both ** 2) - 1) < spread + 0.1, (comp, np.mean(z_both ** 2))
            # The measured deviation from the reference (its own variance taken out) and the stored error.
            dev_once = np.mean((fo - fr)[sel] ** 2 - sr[sel] ** 2)
            dev_both = np.mean((fb - fr)[sel] ** 2 - sr[sel] ** 2)
            ratio = np.sqrt(dev_once / dev_both)
            err_ratio = np.median(so[sel] / sb[sel])
            assert 0.6 < ratio < 0.82 and 0.6 < err_ratio < 0.82, (comp, ratio, err_ratio)
            check = report[comp]
            assert check["tested_pairs"] > 100 and abs(check["mean_z2"] - 1) < 5 * np.sqrt(2.0 / check["tested_pairs"]) + 0.1, check
            print(f"{comp}: stored = weighted mean of both estimates; mean z² {np.mean(z_once ** 2):.3f} (once) "
                  f"{np.mean(z_both ** 2):.3f} (both) over {sel.sum()} bins; deviation from the reference "
                  f"{ratio:.3f} x, stored error {err_ratio:.3f} x a single estimate's; reciprocity check mean z² "
                  f"{check['mean_z2']:.3f} over {check['tested_pairs']} pairs")
    # plan's prediction of each stored slice's L1 (its pilots' own errors, the fold's factor where the
    # pairs are stored once) against the same measure of the tables as written, at the pilots' slices.
    # The pilot tiles are the run's (the same seeds and paths), so what is tested is the fold's
    # factor: the mean's error predicted from one estimate and reciprocity.
    for name in ("once", "both"):
        run(["plan", name + ".toml", "--json", f"plan-{name}.json"])
        with open(os.path.join(TMP, f"plan-{name}.json")) as f:
            predicted = json.load(f)["accuracy"]["l1"]["components"]
        with h5py.File(os.path.join(TMP, name + ".h5"), "r") as h:
            op = h["/grid/projected_solid_angle"][:]
            for comp in ("coherent", "multiple"):
                fs, ss = mh.table(h, comp), mh.table(h, comp, error=True)
                for pilot in predicted[comp]["per_pilot"]:
                    i = pilot["incidence"]
                    stored = max(np.sqrt(2 / np.pi) * np.sum(ss[i, l] * op) / np.sum(np.abs(fs[i, l]) * op)
                                 for l in range(fs.shape[1]))
                    ratio = pilot["rel_l1"] / stored
                    print(f"plan, pairs {name}: {comp} at incidence {i} ({pilot['theta_deg']:.1f} deg) predicts "
                          f"L1 {pilot['rel_l1']:.4f}, the stored table's errors give {stored:.4f} ({ratio:.3f} x)")
                    assert abs(ratio - 1) < 0.05, (name, comp, i, ratio)
    sizes = [os.path.getsize(os.path.join(TMP, f)) for f in ("once.h5", "both.h5")]
    print("file sizes (once, both):", sizes)
    # A SIGKILL while rank 0 folds (1024 slices of 16 x 64 bins: a fold of seconds): the partial file
    # and its journal stay whole, and --resume folds again into the same bytes as an uninterrupted run.
    job("fold", 'pairs = "once"', n_theta=16, n_phi=64, paths=2000)
    run(["run", "fold.toml", "-o", "fold-ref.h5"], mpi=2)
    out = os.path.join(TMP, "fold.h5")
    p = start(["run", "fold.toml"])
    while not os.path.exists(out + ".pairs") and p.poll() is None:
        time.sleep(0.01)
    subprocess.run(["pkill", "-KILL", "-s", str(p.pid)])
    p.wait()
    wait_session_gone(p.pid)
    landed = os.path.exists(out + ".partial")  # else the run had finished before the kill
    if landed:
        assert os.path.exists(out + ".journal")
        r = run(["run", "fold.toml", "--resume"], mpi=2)
        assert "1024 of 1024 slices already complete" in r.stdout + r.stderr, r.stdout + r.stderr
    assert datasets(out) == datasets(os.path.join(TMP, "fold-ref.h5")), "the fold after a kill differs"
    assert not os.path.exists(out + ".partial") and not os.path.exists(out + ".pairs.scratch")
    print("SIGKILL during the fold:", "resumed, the same datasets" if landed else "the run had finished (nothing to resume)")
    r = run(["slice", "once.h5", "--model", "GM", "-o", "once.csv"])
    assert "wrote once.csv" in r.stdout + r.stderr


def folded_l1_model(a, paths):
    """The model's L1 per slice of a table constant over the bins, pairs stored once, where every bin
    of projected solid angle a[i] is an incidence traced with paths[i]: Σ_o sqrt(Ω⊥(o) w_io / N_i),
    w_io = N_i Ω⊥(o) / (N_i Ω⊥(o) + N_o Ω⊥(i)) the partner's weight in the fold (1 for o = i)."""
    w = paths[:, None] * a[None, :] / (paths[:, None] * a[None, :] + paths[None, :] * a[:, None])
    np.fill_diagonal(w, 1.0)
    return np.sum(np.sqrt(a[None, :] * w / paths[:, None]), axis=1)


def equal_error_shares(op, n_theta, n_phi):
    """path_allocation = "equal-error" from its definition, bin by bin (scattering/path_allocation.h):
    the paths N_i that make folded_l1_model the same for every upper incidence bin i of a theta-phi
    grid, the largest 1."""
    n = n_theta * n_phi
    a = op[:n]
    paths = np.ones(n)
    for _ in range(64):
        e2 = paths * folded_l1_model(a, paths) ** 2
        paths = e2 / np.max(e2)
    return paths


def slice_l1(h, comp):
    """Per slice, the L1 its stored errors give: max over wavelengths of sqrt(2/pi) Σ σ Ω⊥ / Σ |f| Ω⊥."""
    sys.path.insert(0, os.path.join(SRC, "python"))
    import microbsdf_h5 as mh  # noqa: E402
    op = h["/grid/projected_solid_angle"][:]
    f, s = mh.table(h, comp), mh.table(h, comp, error=True)
    return np.max(np.sqrt(2 / np.pi) * np.sum(s * op, axis=2) / np.sum(np.abs(f) * op, axis=2), axis=1)


def test_path_allocation():
    """[sampling] path_allocation = "equal-error" with pairs stored once (rough gold, every upper
    bin of 6 x 12 an incidence, coherent + multiple, 2 ranks): each slice is traced with the paths of
    the allocation, recomputed here bin by bin from its definition (/stats/samples; the largest
    paths_per_slice); the same bytes on 1 and 2 ranks; against a reference with 16 times the paths
    the stored errors are honest (mean z² 1 within the estimator's spread); per slice, the L1 the
    stored errors give moves against the same job with the same paths everywhere as the model
    predicts (within 10 %), so that the slices the fold helps least keep their error while the
    others spend fewer paths; `check --slice-paths` lists the same counts; `plan` predicts each pilot
    slice's L1 within 5 % of the stored errors'."""
    job = full_sphere_job
    n_theta, n_phi, paths = 6, 12, 20000
    for name, extra in (("uniform", ""), ("equal", 'path_allocation = "equal-error"'),
                        ("equal1", 'path_allocation = "equal-error"')):
        path = job(name, 'pairs = "once"', n_theta=n_theta, n_phi=n_phi, paths=paths)
        text = open(path).read().replace("[sampling]\n", "[sampling]\n" + extra + "\n")
        open(path, "w").write(text)
    run(["run", "uniform.toml"], mpi=2)
    run(["run", "equal.toml"], mpi=2)
    run(["run", "equal1.toml", "--threads", "1"])
    assert datasets(os.path.join(TMP, "equal.h5")) == datasets(os.path.join(TMP, "equal1.h5")), "1 vs 2 ranks"
    run(["run", job("ref", 'pairs = "both"', n_theta=n_theta, n_phi=n_phi, paths=16 * paths, seed=7)], mpi=2)
    sys.path.insert(0, os.path.join(SRC, "python"))
    import microbsdf_h5 as mh  # noqa: E402
    with h5py.File(os.path.join(TMP, "equal.h5"), "r") as e, h5py.File(os.path.join(TMP, "uniform.h5"), "r") as u, \
            h5py.File(os.path.join(TMP, "ref.h5"), "r") as r:
        op = e["/grid/projected_solid_angle"][:]
        share = equal_error_shares(op, n_theta, n_phi)
        samples = e["/stats/samples"][:]
        assert np.all(np.abs(samples - np.ceil(share * paths)) <= 1), (samples, share * paths)
        assert samples.max() == paths and "equal-error" in e.attrs["path_allocation"].decode()
        # `check --slice-paths` lists the same counts, incidence by incidence.
        run(["check", "equal.toml", "--slice-paths", "equal-paths.csv"])
        with open(os.path.join(TMP, "equal-paths.csv")) as f:
            listed = list(csv.DictReader(f))
        assert [int(r["paths"]) for r in listed] == samples.tolist(), "check --slice-paths"
        assert [int(r["bin"]) for r in listed] == e["/incidence/bin"][:].astype(int).tolist()
        print("paths per ring:", samples[::n_phi], f"mean {samples.mean() / paths:.3f} of paths_per_slice")
        for comp in ("coherent", "multiple"):
            fe, se = mh.table(e, comp), mh.table(e, comp, error=True)
            fr, sr = mh.table(r, comp), mh.table(r, comp, error=True)
            sel = (se > 0) & (sr > 0)
            z = (fe[sel] - fr[sel]) / np.sqrt(se[sel] ** 2 + sr[sel] ** 2)
            spread = 5 * np.sqrt(2.0 / sel.sum())
            assert abs(np.mean(z ** 2) - 1) < spread + 0.1, (comp, np.mean(z ** 2), sel.sum())
            # The model's L1 per slice (a table constant over the bins) with the allocation's paths
            # and with paths_per_slice everywhere: the ratio it predicts against the one measured.
            bins = e["/incidence/bin"][:].astype(int)
            a = op[bins]
            predicted = folded_l1_model(a, samples.astype(float)) / folded_l1_model(a, np.full(len(a), float(paths)))
            measured = slice_l1(e, comp) / slice_l1(u, comp)
            dev = measured / predicted
            worst_e, worst_u = slice_l1(e, comp).max(), slice_l1(u, comp).max()
            print(f"{comp}: mean z² {np.mean(z ** 2):.3f} over {sel.sum()} bins; L1 per slice against the same paths "
                  f"everywhere: measured / predicted {dev.min():.3f}-{dev.max():.3f} (rings "
                  f"{np.round(measured[::n_phi], 3)}); worst slice {worst_e:.4f} against {worst_u:.4f}")
            assert np.all(np.abs(dev - 1) < 0.1), (comp, dev)
            assert worst_e < 1.1 * worst_u, (comp, worst_e, worst_u)
    for name in ("equal",):
        run(["plan", name + ".toml", "--json", f"plan-{name}.json"])
        with open(os.path.join(TMP, f"plan-{name}.json")) as f:
            predicted = json.load(f)["accuracy"]["l1"]
        assert predicted["path_allocation"]["kind"] == "equal-error"
        with h5py.File(os.path.join(TMP, name + ".h5"), "r") as h:
            for comp in ("coherent", "multiple"):
                stored = slice_l1(h, comp)
                for pilot in predicted["components"][comp]["per_pilot"]:
                    i = pilot["incidence"]
                    ratio = pilot["rel_l1"] / stored[i]
                    print(f"plan, equal-error: {comp} at incidence {i} ({pilot['theta_deg']:.1f} deg) predicts "
                          f"L1 {pilot['rel_l1']:.4f}, the stored errors give {stored[i]:.4f} ({ratio:.3f} x)")
                    assert abs(ratio - 1) < 0.05, (comp, i, ratio)


def wm_excess_beyond_noise(a, b, brdf_only=False):
    """Per slice and wavelength, how far the auto table `a` (h5py file) differs from the WM model of
    the full table `b` (the same seeds) beyond noise: sum|f_WM - f_auto| * proj. solid angle, less
    the expected L1 of pure noise and 3 standard deviations. A component auto skipped (on a slice, for
    a guarded one) contributes its full-table noise; one both computed with the same estimator and
    components shares its noise (same seeds); otherwise both errors count. brdf_only: the reflected
    hemisphere only (light from below, inside a dielectric, reflects into the lower half)."""
    op = a["/grid/projected_solid_angle"][:]
    nh = len(op) // 2
    a_est, b_est = a.attrs.get("wave_estimator"), b.attrs.get("wave_estimator")
    from_below = a["/incidence/theta_deg"][:] > 90
    out = []
    for i in range(a["/bsdf/coherent"].shape[0]):
        if brdf_only:
            reflected = np.arange(len(op)) >= nh if from_below[i] else np.arange(len(op)) < nh
            op_i = np.where(reflected, op, 0)
        else:
            op_i = op
        for l in range(a["/bsdf/coherent"].shape[1]):
            diff = np.zeros(len(op_i))
            var = np.zeros(len(op_i))
            for c in ("coherent", "incoherent", "multiple"):
                if c not in b["bsdf"]:
                    continue
                full_c = b[f"/bsdf/{c}"][i, l].astype(float)
                auto_c = a[f"/bsdf/{c}"][i, l].astype(float) if c in a["bsdf"] else 0 * full_c
                diff += full_c - auto_c
                # A guarded component auto skipped on this slice (held as 0, the check confirmed the
                # skip) is skipped there: its full-table noise counts as for one auto never held.
                skipped_here = c == "incoherent" and "/stats/diffraction_reenabled" in a and \
                    not a["/stats/diffraction_reenabled"][i]
                if c not in a["bsdf"] or skipped_here:
                    var += b[f"/bsdf_stderr/{c}"][i, l].astype(float) ** 2
                elif c == "incoherent" and (a_est != b_est or ("lost" in a["bsdf"]) != ("lost" in b["bsdf"])):
                    # Different estimators, or one that also computed the masked field (`lost`): the
                    # same seeds give other samples (measured: incoherent tables up to 100 apart in
                    # a bin), so the noise is independent.
                    var += (b[f"/bsdf_stderr/{c}"][i, l].astype(float) ** 2
                            + a[f"/bsdf_stderr/{c}"][i, l].astype(float) ** 2)
            l1 = np.sum(np.abs(diff) * op_i)
            sd = np.sqrt(var) * op_i
            out.append(l1 - np.sqrt(2 / np.pi) * sd.sum() - 3 * np.sqrt(np.sum(sd ** 2)))
    return out


def effects_job(path, geometry, material, scene, components=None,
                incidence="[[0.0, 0.0], [40.0, 0.0], [70.0, 30.0]]", effects="", directions=""):
    with open(path, "w") as f:
        f.write(f"""[geometry]
{geometry}
[material]
{material}
[spectrum]
wavelengths_nm = [500.0, 600.0]
[directions]
n_theta = 8
n_phi = 16
incidence = {incidence}
{directions}
[scene]
{scene}
tolerance = 0.02
[effects]
components = {json.dumps(components or ["auto"])}
{effects}
[sampling]
paths_per_slice = 50000
wave_samples_per_bin = 1024
seed = 5
[output]
path = "out.h5"
""")
    return path



def test_effects_skip_verified():
    """A skip the pilots could not see is caught on the tile: a mirror V-groove (period 2 µm, apex
    125°) with listed incidences and a pilot budget that affords three geometric pilots (the most
    grazing 32°@90°, 0° and the median 25°@90°), which stay below the grooves' inter-reflection
    threshold, so the planner drops `multiple`; the unpiloted 20°@0° slice has about 0.1 of it.
    Every slice verifies the skip; that one computes it after all. Per slice and wavelength the auto
    table (WM) is within the tolerance of the full one, and `info` says which slice was re-enabled.
    (With the default budget every listed incidence is piloted and `multiple` stays on.)"""
    geo = 'kind = "ridged"\nsize_um = [2.0, 0.3]\nperiod_um = 2.0\napex_angle_deg = 125.0'
    inc = "[[0.0, 0.0], [20.0, 0.0], [25.0, 90.0], [30.0, 90.0], [32.0, 90.0]]"
    # 0.24 x 5 tiles x 50 000 / 20 000 paths = 3 geometric pilots.
    auto = effects_job(os.path.join(TMP, "vg-auto.toml"), geo, 'name = "mirror"', "", incidence=inc,
                       effects="pilot_budget = 0.24")
    full = effects_job(os.path.join(TMP, "vg-full.toml"), geo, 'name = "mirror"', "", ["coherent", "incoherent", "multiple"],
                       incidence=inc)
    r = run(["run", auto, "-o", "vg-auto.h5"], mpi=2)
    run(["run", full, "-o", "vg-full.h5"], mpi=2)
    log = r.stdout + r.stderr
    assert "multiple    off" in log, log
    # The warning comes from the rank that computed tile 1 (its log file; rank 0 prints to the console too).
    folder = os.path.join(TMP, "vg-auto.h5.logs")
    logs = "".join(open(os.path.join(folder, n)).read() for n in sorted(os.listdir(folder)))
    assert "tile 1 (theta_i 20 deg, phi_i 0 deg): multiple scattering up to" in logs + log, logs + log
    with h5py.File(os.path.join(TMP, "vg-auto.h5"), "r") as a, h5py.File(os.path.join(TMP, "vg-full.h5"), "r") as b:
        tol = json.loads(a.attrs["effects_plan"])["tolerance"]
        assert list(a["/stats/multiple_reenabled"][:]) == [0, 1, 0, 0, 0], a["/stats/multiple_check"][:]
        assert a["/stats/multiple_check"][1] > 0.05, a["/stats/multiple_check"][:]
        op = a["/grid/projected_solid_angle"][:]
        wm = lambda f: sum(f["/bsdf/" + c][:].astype(float) for c in ("coherent", "incoherent", "multiple"))  # noqa: E731
        fa, fb = wm(a), wm(b)
        for i in range(fa.shape[0]):
            for l in range(fa.shape[1]):
                d = float(np.sum(np.abs(fa[i, l] - fb[i, l]) * op))
                assert d <= tol, f"slice {i}, λ {l}: auto differs from full by {d:.4f} (tolerance {tol})"
        multiple_full = float(np.sum(b["/bsdf/multiple"][1, 0] * op))
    info = run(["info", "vg-auto.h5"]).stdout
    assert "computed after all, on slice(s) 1" in info, info
    print(f"V-groove: multiple skipped by the pilots; slice 1 (20°@0°) re-enabled ({multiple_full:.3f} of multiple "
          f"scattering in the full table); every slice within the tolerance {tol} of the full table")


def test_effects_diffraction_verified():
    """A diffraction skip the pilots could not see is caught on the tile: a flat mirror under a 2 mm
    coherence length lit along 66 exact directions (more than the 64 the planner's closed form for a
    flat interface covers, so the pilots decide), 65 of them reflected into the middle of a bin, where
    the window's 0.02 deg lobe stays in one bin as the geometric spike does (WS - GS ~ 3e-8): the
    pilots (six, none at 22.5 deg) turn diffraction off. At 22.5 deg the specular direction lies on the
    edge between two rings: the lobe splits between them and WS - GS is about 1. The tiles the pilots
    ran as the job does keep their figure (incoherent stored as 0); every other tile computes its wave
    term, and the 22.5 deg slice, past the tolerance, keeps it. Per slice and wavelength the auto
    table is within the tolerance of the full one, auto does no more wave work than the full table,
    and `info` names the re-enabled slice."""
    thetas = [5.625, 10.0, 16.875, 20.0, 28.125, 30.0, 39.375, 42.0, 50.625, 53.0, 61.875, 64.0, 73.125]
    directions_deg = [[t, p] for p in (11.25, 78.75, 146.25, 213.75, 281.25) for t in thetas]
    directions_deg.insert(3, [22.5, 11.25])
    n = len(directions_deg)
    inc = json.dumps(directions_deg)
    geo, mat = 'kind = "flat"\nsize_um = [10.0, 10.0]', 'name = "mirror"'
    scene, directions = "coherence_length_um = 2000.0", 'incidence_sampling = "exact"'
    auto = effects_job(os.path.join(TMP, "edge-auto.toml"), geo, mat, scene, incidence=inc, directions=directions)
    full = effects_job(os.path.join(TMP, "edge-full.toml"), geo, mat, scene, ["coherent", "incoherent", "multiple"],
                       incidence=inc, directions=directions)
    r = run(["run", auto, "-o", "edge-auto.h5"], mpi=2)
    run(["run", full, "-o", "edge-full.h5"], mpi=2)
    log = r.stdout + r.stderr
    assert "incoherent  off" in log, log
    folder = os.path.join(TMP, "edge-auto.h5.logs")
    logs = "".join(open(os.path.join(folder, n)).read() for n in sorted(os.listdir(folder)))
    assert "tile 3 (theta_i 22.5 deg, phi_i 11.2 deg): diffraction changes the slice by up to" in logs + log, logs + log
    with h5py.File(os.path.join(TMP, "edge-auto.h5"), "r") as a, h5py.File(os.path.join(TMP, "edge-full.h5"), "r") as b:
        plan = json.loads(a.attrs["effects_plan"])
        tol = plan["tolerance"]
        verified = {v["incidence"] for d in plan["decisions"] if d["effect"] == "incoherent"
                    for v in d["pilot_verified"]}
        assert 3 not in verified and len(verified) >= 3, plan
        check = a["/stats/diffraction_check"][:]
        assert np.all(np.isfinite(check)), check
        assert list(a["/stats/diffraction_reenabled"][:]) == [int(i == 3) for i in range(n)], check
        assert check[3] > 0.5, check
        # Slices a pilot verified hold no incoherent and drew no wave sample; the others drew the full table's.
        for i in range(n):
            if i in verified:
                assert a["/stats/wave_samples"][i] == 0 and not np.any(a["/bsdf/incoherent"][i]), i
            else:
                assert a["/stats/wave_samples"][i] == b["/stats/wave_samples"][i], i
        op = a["/grid/projected_solid_angle"][:]
        wm = lambda f: sum(f["/bsdf/" + c][:].astype(float) for c in ("coherent", "incoherent", "multiple"))  # noqa: E731
        fa, fb = wm(a), wm(b)
        for i in range(fa.shape[0]):
            for l in range(fa.shape[1]):
                d = float(np.sum(np.abs(fa[i, l] - fb[i, l]) * op))
                assert d <= tol, f"slice {i}, λ {l}: auto differs from full by {d:.4f} (tolerance {tol})"
        incoherent_full = float(np.sum(np.abs(b["/bsdf/incoherent"][3, 0]) * op))
        samples = [float(np.sum(f["/stats/wave_samples"][:])) for f in (a, b)]
    info = run(["info", "edge-auto.h5"]).stdout
    assert f"diffraction: skipped by the effects planner, verified on {n} slice(s)" in info, info
    assert "computed after all, on slice(s) 3" in info, info
    print(f"flat mirror, exact incidences: diffraction skipped by {len(verified)} pilots; slice 3 (22.5 deg, on a ring "
          f"edge) re-enabled (check {check[3]:.3f}; the full table's incoherent there: {incoherent_full:.3f}); every "
          f"slice within {tol} of the full table; wave samples {samples[0]:.3g} against {samples[1]:.3g}")


def test_export_zemax():
    """`export --format zemax` read back by an independent reader (zemax_reader.py, written from the
    format's description): a statistical GGX conductor (alpha 0.3, every incidence of a 12 x 24 grid,
    isotropic: one sample rotation) and an anisotropic sine grating at a 2 x 2 grid of listed
    incidences (two rotations: ASymmetrical4D, the format description's spelling; at 45 deg to the grooves its orders lie off the plane
    of incidence, so the sense of the scatter azimuth matters). Per angle of incidence the file's TIS equals the
    table's hemispherical integral sum f * proj. solid angle over the reflected bins, computed here
    from the HDF5 file (within 0.5 %); the tabulated values integrate to it (within 2 %: the
    resampling's own error on the coarse test grids); at random scatter directions of every block,
    placed by the format's definition of radial and azimuth, the reader's bilinear lookup agrees with
    `microbsdf eval` on the table (within 3 % of the slice's peak).
    Incidences that are not a theta x phi grid are refused with exit 2 and the reason.
    A BTDF (rough glass of index 1.5): AngleOfIncidence the refracted angles of Snell's law, TIS the
    table's transmitted integral (0.5 %), the lookup about the refracted direction against `eval`
    (3 % of the peak); a conductor's BTDF refused. XYZ of a mirror (spectrally flat): each
    tristimulus set is the monochrome f times one constant, 1 for Y."""
    sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
    from zemax_reader import ZemaxBsdf
    ggx = os.path.join(TMP, "ggx.toml")
    with open(ggx, "w") as f:
        f.write("""[geometry]\nkind = "statistical"\nndf = "ggx"\nalpha = 0.3\n[material]\nname = "Al"
[spectrum]\nwavelengths_nm = [500.0, 600.0]\n[directions]\nn_theta = 12\nn_phi = 24\nincidence = "all"
[effects]\ncomponents = ["coherent", "multiple"]\n[sampling]\npaths_per_slice = 100000\nseed = 3
[output]\npath = "ggx.h5"\n""")
    run(["run", ggx, "-o", "ggx.h5"], mpi=2)
    grating = effects_job(os.path.join(TMP, "grating.toml"),
                          'kind = "sine-grating"\nsize_um = [2.0, 0.3]\nperiod_um = 2.0\namplitude_um = 0.2',
                          'name = "Al"', "coherence_length_um = 50.0", ["coherent", "incoherent", "multiple"],
                          incidence="[[10.0, 0.0], [40.0, 0.0], [10.0, 45.0], [40.0, 45.0]]")
    run(["run", grating, "-o", "grating.h5"], mpi=2)
    rng = np.random.default_rng(11)
    for name, h5name, model, rotations in (("GGX", "ggx.h5", "GM", 1), ("sine grating", "grating.h5", "WM", 2)):
        with open(os.path.join(TMP, f"{h5name}.bsdf"), "w") as f:
            f.write("an older file: replaced whole or not at all\n")
        run(["export", h5name, "--format", "zemax", "--model", model, "--lambda-nm", "500", "-o", f"{h5name}.bsdf"])
        assert not os.path.exists(os.path.join(TMP, f"{h5name}.bsdf.partial"))
        z = ZemaxBsdf(os.path.join(TMP, f"{h5name}.bsdf"))
        assert len(z.enums["SampleRotation"]) == rotations, z.enums["SampleRotation"]
        assert z.keys["Symmetry"] == ("ASymmetrical4D" if rotations > 1 else "Asymmetrical"), z.keys
        worst_tis = worst_integral = worst_lookup = 0.0
        with h5py.File(os.path.join(TMP, h5name), "r") as h:
            op = h["/grid/projected_solid_angle"][:]
            nh = len(op) // 2
            comps = {"GM": ("coherent", "multiple"), "WM": ("coherent", "incoherent", "multiple")}[model]
            table = sum(h["/bsdf/" + c][:, 0, :].astype(float) for c in comps)
            th, ph = h["/incidence/theta_deg"][:], h["/incidence/phi_deg"][:]
            for ri, rot in enumerate(z.enums["SampleRotation"]):
                for k, aoi in enumerate(z.enums["AngleOfIncidence"]):
                    i = int(np.argmin(np.abs(th - aoi) + np.abs(ph - rot)))
                    assert abs(th[i] - aoi) < 1e-6 and abs(ph[i] - rot) < 1e-6, (aoi, rot)
                    tis_h5 = float(np.sum(table[i, :nh] * op[:nh]))
                    worst_tis = max(worst_tis, abs(z.tis[ri, k] - tis_h5) / tis_h5)
                    worst_integral = max(worst_integral, abs(z.integral(ri, k) - z.tis[ri, k]) / z.tis[ri, k])
                    # Scatter directions in the sample's frame, from the format's definition.
                    t, p = np.radians(aoi), np.radians(rot)
                    wi = np.array([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)])
                    s = np.array([-wi[0], -wi[1], wi[2]])
                    e1 = np.array([0, 0, 1.0]) - s * s[2]
                    e1 /= np.linalg.norm(e1)
                    e2 = np.cross(s, e1)
                    peak = float(np.max(z.data[ri][k]))
                    for _ in range(4):
                        r, a = rng.uniform(0, 60), rng.uniform(0, 360)
                        wo = np.cos(np.radians(r)) * s + np.sin(np.radians(r)) * (
                            np.cos(np.radians(a)) * e1 + np.sin(np.radians(a)) * e2)
                        if wo[2] <= 0.05:
                            continue
                        to, po = np.degrees(np.arccos(wo[2])), np.degrees(np.arctan2(wo[1], wo[0])) % 360
                        out = run(["eval", h5name, "--model", model, "--wi", f"{aoi},{rot}", "--wo", f"{to},{po}"]).stdout
                        f_eval = float([ln for ln in out.splitlines() if ln.startswith("500,")][0].split(",")[1])
                        worst_lookup = max(worst_lookup, abs(z.lookup(ri, k, r, a) - f_eval) / peak)
        assert worst_tis < 0.005, f"{name}: TIS differs from the table's integral by {worst_tis:.2%}"
        assert worst_integral < 0.02, f"{name}: the data integrate {worst_integral:.2%} away from TIS"
        assert worst_lookup < 0.03, f"{name}: reader's lookup and eval differ by {worst_lookup:.2%} of the peak"
        print(f"{name}: {len(z.enums['AngleOfIncidence'])} angles x {rotations} rotation(s), "
              f"{os.path.getsize(os.path.join(TMP, h5name + '.bsdf')) / 1e6:.1f} MB; TIS vs table "
              f"{worst_tis:.2e}, data integral vs TIS {worst_integral:.2%}, lookup vs eval {worst_lookup:.2%} of the peak")
    bad = effects_job(os.path.join(TMP, "bad.toml"), 'kind = "flat"\nsize_um = [10.0, 10.0]', 'name = "Al"',
                      "coherence_length_um = 50.0", ["coherent"], incidence="[[10.0, 0.0], [40.0, 30.0]]")
    run(["run", bad, "-o", "bad.h5"], mpi=2)
    r = run(["export", "bad.h5", "--format", "zemax", "-o", "bad.bsdf"], expect=2)
    assert "not a theta x phi grid" in r.stderr, r.stderr
    assert not os.path.exists(os.path.join(TMP, "bad.bsdf"))
    print("listed incidences off a grid: refused (exit 2) and nothing written")
    # A BTDF about the refracted direction: glass of constant index 1.5, so that Snell is checked here.
    glass = os.path.join(TMP, "glass.toml")
    with open(glass, "w") as f:
        f.write("""[geometry]\nkind = "statistical"\nndf = "ggx"\nalpha = 0.3\n[material]\nkind = "dielectric"\nior = 1.5
[spectrum]\nwavelengths_nm = [550.0]\n[directions]\nn_theta = 12\nn_phi = 24\nincidence = "all"
[effects]\ncomponents = ["coherent", "multiple"]\n[sampling]\npaths_per_slice = 30000\nseed = 3
[output]\npath = "glass.h5"\n""")
    run(["run", glass, "-o", "glass.h5"], mpi=2)
    run(["export", "glass.h5", "--format", "zemax", "--side", "transmission", "-o", "glass-btdf.bsdf"])
    z = ZemaxBsdf(os.path.join(TMP, "glass-btdf.bsdf"))
    assert z.keys["ScatterType"] == "BTDF", z.keys
    with h5py.File(os.path.join(TMP, "glass.h5"), "r") as h:
        op = h["/grid/projected_solid_angle"][:]
        nh = len(op) // 2
        table = sum(h["/bsdf/" + c][:, 0, :].astype(float) for c in ("coherent", "multiple"))
        th, ph = h["/incidence/theta_deg"][:], h["/incidence/phi_deg"][:]
    thetas = np.unique(th[th < 90])
    snell = np.degrees(np.arcsin(np.sin(np.radians(thetas)) / 1.5))
    assert np.allclose(z.enums["AngleOfIncidence"], snell, atol=1e-4), (z.enums["AngleOfIncidence"], snell)
    worst_tis = worst_lookup = 0.0
    rot = z.enums["SampleRotation"][0]
    for k, theta in enumerate(thetas):
        i = int(np.argmin(np.abs(th - theta) + np.abs(ph - rot)))
        tis_h5 = float(np.sum(table[i, nh:] * op[nh:]))
        worst_tis = max(worst_tis, abs(z.tis[0, k] - tis_h5) / tis_h5)
        tt, p = np.radians(z.enums["AngleOfIncidence"][k]), np.radians(rot)
        t = np.array([-np.sin(tt) * np.cos(p), -np.sin(tt) * np.sin(p), -np.cos(tt)])
        e1 = np.array([0, 0, -1.0]) - t * (-t[2])
        e1 = e1 / np.linalg.norm(e1) if np.linalg.norm(e1) > 1e-9 else np.array([np.cos(p), np.sin(p), 0.0])
        e2 = np.cross(t, e1)
        peak = float(np.max(z.data[0][k]))
        for _ in range(3):
            r, a = rng.uniform(0, 40), rng.uniform(0, 360)
            wo = np.cos(np.radians(r)) * t + np.sin(np.radians(r)) * (np.cos(np.radians(a)) * e1 + np.sin(np.radians(a)) * e2)
            if wo[2] >= -0.05:
                continue
            to, po = np.degrees(np.arccos(wo[2])), np.degrees(np.arctan2(wo[1], wo[0])) % 360
            out = run(["eval", "glass.h5", "--wi", f"{theta},{rot}", "--wo", f"{to},{po}"]).stdout
            f_eval = float([ln for ln in out.splitlines() if ln.startswith("550,")][0].split(",")[1])
            worst_lookup = max(worst_lookup, abs(z.lookup(0, k, r, a) - f_eval) / peak)
    print(f"BTDF (index 1.5): AngleOfIncidence = Snell's refracted angles; TIS vs the table's transmitted "
          f"integral {worst_tis:.2e}; lookup about the refracted direction vs eval {worst_lookup:.2%} of the peak")
    assert worst_tis < 0.005 and worst_lookup < 0.03, (worst_tis, worst_lookup)
    r = run(["export", "grating.h5", "--format", "zemax", "--side", "transmission", "-o", "al.bsdf"], expect=2)
    assert "conductor transmits nothing" in r.stderr, r.stderr
    # XYZ of a spectrally flat table (a mirror: every wavelength takes the same paths): each
    # tristimulus set is the monochrome f times one constant, Y's being 1 (Y of a flat spectrum 1).
    mirror = os.path.join(TMP, "mirror.toml")
    with open(ggx) as f:
        text = f.read()
    with open(mirror, "w") as f:
        f.write(text.replace('name = "Al"', 'name = "mirror"').replace("[500.0, 600.0]", "[450.0, 550.0, 650.0]")
                .replace("100000", "20000").replace('"ggx.h5"', '"mirror.h5"'))
    run(["run", mirror, "-o", "mirror.h5"], mpi=2)
    run(["export", "mirror.h5", "--format", "zemax", "--colour", "xyz", "-o", "mirror-xyz.bsdf"])
    run(["export", "mirror.h5", "--format", "zemax", "--lambda-nm", "550", "-o", "mirror-550.bsdf"])
    x, m = ZemaxBsdf(os.path.join(TMP, "mirror-xyz.bsdf")), ZemaxBsdf(os.path.join(TMP, "mirror-550.bsdf"))
    assert x.keys["SpectralContent"] == "XYZ" and len(x.data_sets) == 3, x.keys
    mono = np.array(m.data[0])
    factors = []
    for c in range(3):
        block = np.array(x.data_sets[c][0])
        big = mono > 1e-3 * mono.max()
        ratio = block[big] / mono[big]
        assert np.ptp(ratio) < 2e-5 * np.mean(ratio), (c, np.ptp(ratio))
        assert np.allclose(x.tis_sets[c][0], np.mean(ratio) * m.tis[0], rtol=2e-5), c
        factors.append(float(np.mean(ratio)))
    assert abs(factors[1] - 1) < 2e-5, factors
    print(f"XYZ of a mirror: each set the monochrome f times {np.round(factors, 5)} (TIS likewise)")


def rgl_ggx_closed_form(alpha_x, alpha_y, wi, wo):
    """Single scattering of a GGX mirror: D G2 / (4 cos_i cos_o) with the height-correlated Smith G2
    (Heitz 2014, Eqs. 85 and 99)."""
    def lam(w):
        t2 = (w[0] ** 2 + w[1] ** 2) / w[2] ** 2
        if t2 == 0:
            return 0.0
        a2 = (w[0] ** 2 * alpha_x ** 2 + w[1] ** 2 * alpha_y ** 2) / (w[0] ** 2 + w[1] ** 2)
        return (-1 + np.sqrt(1 + a2 * t2)) / 2
    h = (wi + wo) / np.linalg.norm(wi + wo)
    d = 1 / (np.pi * alpha_x * alpha_y * (h[0] ** 2 / alpha_x ** 2 + h[1] ** 2 / alpha_y ** 2 + h[2] ** 2) ** 2)
    return d / (1 + lam(wi) + lam(wo)) / (4 * wi[2] * wo[2])


def rgl_random_pairs(rng, alpha_x, alpha_y, n, max_theta_deg):
    """n pairs (wi, wo) with wi uniform in cos theta up to max_theta_deg and wo reflected about a half
    vector drawn from the lobe (where f is worth comparing), both above max_theta_deg's cosine."""
    pairs, cos_max = [], np.cos(np.radians(max_theta_deg))
    while len(pairs) < n:
        t, p = np.arccos(rng.uniform(cos_max, 1)), rng.uniform(0, 2 * np.pi)
        wi = np.array([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)])
        m = np.array([alpha_x * rng.normal(), alpha_y * rng.normal(), 1.0])
        m /= np.linalg.norm(m)
        wo = 2 * np.dot(wi, m) * m - wi
        if wo[2] >= cos_max:
            pairs.append((wi, wo))
    return pairs


def rgl_eval_pairs(h5name, pairs, name):
    """`microbsdf eval --pairs` on the HDF5 table: f per wavelength for each pair."""
    def angles(w):
        return f"{np.degrees(np.arccos(np.clip(w[2], -1, 1)))},{np.degrees(np.arctan2(w[1], w[0])) % 360}"
    with open(os.path.join(TMP, name), "w") as f:
        f.write("# theta_i,phi_i,theta_o,phi_o\n" + "\n".join(f"{angles(a)},{angles(b)}" for a, b in pairs) + "\n")
    out = run(["eval", h5name, "--model", "GS", "--pairs", name]).stdout.splitlines()
    assert out[1].startswith("theta_i,phi_i,theta_o,phi_o,f_"), out[:2]
    return np.array([[float(x) for x in line.split(",")[4:]] for line in out[2:]])


def rgl_table_albedo(name, theta_deg, phi_deg):
    """The HDF5 table's albedo (sum of f * projected solid angle over the reflected bins) per
    wavelength for light from (theta_deg, phi_deg): the incidences at the azimuth nearest phi_deg on
    each ring, blended linearly in theta between the two rings around theta_deg (held beyond the
    first and last), as `eval` blends an isotropic table's rings."""
    with h5py.File(os.path.join(TMP, f"{name}.h5"), "r") as h:
        op = h["/grid/projected_solid_angle"][:]
        nh = len(op) // 2
        th, ph = h["/incidence/theta_deg"][:], h["/incidence/phi_deg"][:]
        bsdf = h["/bsdf/coherent"][...].astype(float)
    rings = np.unique(np.round(th, 9))
    per_ring = []
    for r in rings:
        on = np.flatnonzero(np.isclose(th, r))
        gap = np.abs((ph[on] - phi_deg + 180) % 360 - 180)
        k = on[np.argmin(gap)]
        per_ring.append(np.sum(bsdf[k, :, :nh] * op[:nh], axis=1))
    per_ring = np.array(per_ring)
    return np.array([np.interp(theta_deg, rings, per_ring[:, q]) for q in range(per_ring.shape[1])])


def rgl_furnace_error(b, name, thetas_deg, phis_deg=(0.0,)):
    """Largest relative difference between the albedo a path tracer sees through the reader
    (RglBsdf.furnace: the mean of its sampler's weights) and the table's own, over the incidences
    thetas x phis; each difference is also held to 4 standard errors of the furnace's mean."""
    worst = 0.0
    for t in thetas_deg:
        for p in phis_deg:
            tr, pr = np.radians(t), np.radians(p)
            wi = np.array([np.sin(tr) * np.cos(pr), np.sin(tr) * np.sin(pr), np.cos(tr)])
            mean, se = b.furnace(wi)
            want = rgl_table_albedo(name, t, p)
            worst = max(worst, float(np.max(np.abs(mean / want - 1))))
            assert np.all(np.abs(mean - want) < 0.01 * want + 4 * se), (name, t, p, mean, se, want)
    return worst


def rgl_sampled_pairs(b, rng, n, max_theta_deg):
    """n pairs (wi, wo) as a renderer makes them: wi uniform in cos theta up to max_theta_deg, wo
    drawn by the reader's own sampler (BRDF::sample) from wi, kept off the specular ring
    (|cos theta_i - cos theta_o| > 0.05, where a writer confusing the two cosines shows) and above
    max_theta_deg."""
    pairs, cos_max = [], np.cos(np.radians(max_theta_deg))
    while len(pairs) < n:
        t, p = np.arccos(rng.uniform(cos_max, 1)), rng.uniform(-np.pi, np.pi)
        wi = np.array([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)])
        wo, pdf, _ = b.incidence(wi).sample(rng.random(1), rng.random(1))
        if pdf[0] > 0 and wo[0, 2] >= cos_max and abs(wo[0, 2] - wi[2]) > 0.05:
            pairs.append((wi, wo[0]))
    return pairs


def test_export_rgl():
    """`export --format rgl` read back by a reader that does what the renderers do (rgl_reader.py,
    following the reference loader rgl-epfl/brdf-loader's powitacq.inl: its structure checks, its
    Marginal2D warps, eval = spectra * ndf / (4 sigma) taken as f cos(theta_o), pdf and sample).
    Statistical GGX mirrors, isotropic at alpha 0.2 (60 x 120 bins, 2.4 M paths per slice: the
    narrower lobe needs the finer bins) and 0.6 (30 x 60 bins, 1.2 M paths) and anisotropic at
    (0.25, 0.6) with three wavelengths (12 x 24 bins), every incidence bin.
    - White furnace: the mean of the reader's sampler weights (its albedo as a path tracer sees it)
      within 1 % (+ 4 standard errors) of the table's own albedo from 5 to 85 deg, at and between
      the file's incidence nodes (the anisotropic file at four azimuths).
    - At 400 pairs drawn by the reader's own sampler off the specular ring (cos theta_i and
      cos theta_o differ by more than 0.05): the file against `eval`, median within 3 %; reciprocity
      f(wi, wo) = f(wo, wi) as the reader returns f, median within 3 % and no worse than the table's
      own.
    - At 1000 random pairs in the lobe (wi up to 80 deg): the isotropic files within 2 % of the
      closed form D G2 / (4 cos cos) (median; the tables' own bin averaging and noise are about
      1.5 % there), and no farther from it than the table itself (median and 90th percentile within
      +1 point): the export adds no error of its own; the file against `eval` median within 2.5 %.
    - The RGB file of the neutral mirror: the spectral f times one grey colour.
    - A flat mirror (12 x 24 bins), whose lobe is far narrower than the nodes: the file's albedo the
      table's within 1 % near and away from the normal, and a warning naming each grazing incidence
      the format cannot resolve.
    Refused with exit 2 and nothing written: --side transmission; an anisotropic table of listed
    incidences."""
    sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
    from rgl_reader import RglBsdf
    cases = (("iso0.2", 0.2, 0.2, 60, 120, "0.2", "[550.0]", 2400000),
             ("iso0.6", 0.6, 0.6, 30, 60, "0.6", "[550.0]", 1200000),
             ("aniso", 0.25, 0.6, 12, 24, "[0.25, 0.6]", "[450.0, 550.0, 650.0]", 50000))
    rng = np.random.default_rng(17)
    for name, ax, ay, n_theta, n_phi, alpha, nm, paths in cases:
        with open(os.path.join(TMP, f"{name}.toml"), "w") as f:
            f.write(f"""[geometry]\nkind = "statistical"\nndf = "ggx"\nalpha = {alpha}\n[material]\nname = "mirror"
[spectrum]\nwavelengths_nm = {nm}\n[directions]\nn_theta = {n_theta}\nn_phi = {n_phi}\nincidence = "all"
[effects]\ncomponents = ["coherent"]\n[sampling]\npaths_per_slice = {paths}\nseed = 3\n[output]\npath = "{name}.h5"\n""")
        run(["run", f"{name}.toml", "-o", f"{name}.h5"], mpi=2)
        t0 = time.time()
        r = run(["export", f"{name}.h5", "--format", "rgl", "--model", "GS", "-o", f"{name}.bsdf"])
        seconds = time.time() - t0
        assert not os.path.exists(os.path.join(TMP, f"{name}.bsdf.partial"))
        b = RglBsdf(os.path.join(TMP, f"{name}.bsdf"))
        assert b.isotropic == (ax == ay), name
        # What a path tracer sees: the albedo from the reader's sampler, at and between the nodes.
        phis = (0.0,) if ax == ay else (7.5, 52.5, 97.5, 142.5)
        worst = rgl_furnace_error(b, name, range(5, 90, 10), phis)
        print(f"{name}: white furnace through the reader vs the table's albedo, 5-85 deg: worst {worst:.2%}")
        assert worst < 0.01, (name, worst)
        # Off the specular ring, at directions the reader's sampler draws: f against `eval`, and
        # reciprocity of f as the reader returns it.
        sampled = rgl_sampled_pairs(b, rng, 400, 80)
        table = rgl_eval_pairs(f"{name}.h5", sampled, f"{name}.sampled")
        back = rgl_eval_pairs(f"{name}.h5", [(wo, wi) for wi, wo in sampled], f"{name}.sampled-back")
        f_file = np.array([b.f(wi, wo) for wi, wo in sampled])
        f_back = np.array([b.f(wo, wi) for wi, wo in sampled])
        off, recip_file, recip_table = np.abs(f_file / table - 1), np.abs(f_back / f_file - 1), np.abs(back / table - 1)
        print(f"{name}: sampled off-specular pairs: file vs eval median {np.median(off):.2%} p90 "
              f"{np.percentile(off, 90):.2%}; reciprocity file {np.median(recip_file):.2%}, table "
              f"{np.median(recip_table):.2%} (median)")
        assert np.median(off) < 0.03, (name, np.median(off))
        assert np.median(recip_file) < 0.03 and np.median(recip_file) <= np.median(recip_table) + 0.005, \
            (name, np.median(recip_file), np.median(recip_table))
        pairs = rgl_random_pairs(rng, ax, ay, 1000, 80)
        table = rgl_eval_pairs(f"{name}.h5", pairs, f"{name}.pairs")
        exported = np.array([b.f(wi, wo) for wi, wo in pairs])
        closed = np.array([rgl_ggx_closed_form(ax, ay, wi, wo) for wi, wo in pairs])[:, None]
        assert np.all(np.isfinite(exported)) and np.all(exported >= 0)
        rel = np.abs(exported / table - 1)
        own, ours = np.abs(table / closed - 1), np.abs(exported / closed - 1)
        print(f"{name}: {os.path.getsize(os.path.join(TMP, name + '.bsdf')) / 1e6:.2f} MB in {seconds:.1f} s; "
              f"file vs table median {np.median(rel):.2%} p90 {np.percentile(rel, 90):.2%}; vs closed form: file "
              f"{np.median(ours):.2%}/{np.percentile(ours, 90):.2%}, table {np.median(own):.2%}/"
              f"{np.percentile(own, 90):.2%} (median/p90)")
        assert np.median(rel) < 0.025, (name, np.median(rel), np.percentile(rel, 90))
        assert np.median(ours) < np.median(own) + 0.01, (name, np.median(ours), np.median(own))
        if ax == ay:
            assert np.median(ours) < 0.02, (name, np.median(ours))
        assert np.percentile(ours, 90) < np.percentile(own, 90) + 0.01, name
        if name == "aniso":
            run(["export", f"{name}.h5", "--format", "rgl", "--model", "GS", "--colour", "rgb", "-o", "rgb.bsdf"])
            c = RglBsdf(os.path.join(TMP, "rgb.bsdf"))
            assert "rgb" in c.fields and "spectra" not in c.fields
            rgb = np.array([c.f(wi, wo) for wi, wo in pairs[:200]])
            # A neutral mirror's colour is that of a flat spectrum at every pair: one ratio per channel to
            # the spectral f, within 2 % of grey (three samples of a flat spectrum are not exactly white E).
            ratio = rgb / exported[:200, 1:2]
            assert np.allclose(ratio, np.median(ratio, axis=0), rtol=2e-3), "rgb is not the spectral f's colour"
            assert np.allclose(np.median(ratio, axis=0), 1, atol=0.02), np.median(ratio, axis=0)
            print(f"aniso: rgb file of the neutral mirror: the spectral f times {np.median(ratio, axis=0).round(4)}")
    # A flat mirror: a lobe (the specular bin, through the interpolation between bin centres) far
    # narrower than the nodes; the file keeps the table's albedo, and says where it cannot.
    with open(os.path.join(TMP, "flat.toml"), "w") as f:
        f.write("""[geometry]\nkind = "flat"\nsize_um = [10.0, 10.0]\n[material]\nname = "mirror"
[spectrum]\nwavelengths_nm = [550.0]\n[directions]\nn_theta = 12\nn_phi = 24\nincidence = "all"
[effects]\ncomponents = ["coherent"]\n[sampling]\npaths_per_slice = 2000\nseed = 3\n[output]\npath = "flat.h5"\n""")
    run(["run", "flat.toml", "-o", "flat.h5"], mpi=2)
    r = run(["export", "flat.h5", "--format", "rgl", "-o", "flat.bsdf"])
    b = RglBsdf(os.path.join(TMP, "flat.bsdf"))
    worst = rgl_furnace_error(b, "flat", (3.75, 33.75, 63.75), (7.5,))
    unresolved = re.findall(r"at theta_i ([0-9.]+) deg", r.stderr)
    print(f"flat mirror: albedo of the file vs the table's at 3.75, 33.75, 63.75 deg: worst {worst:.2%}; "
          f"unresolved (warned) at theta_i {sorted(set(unresolved))} deg")
    assert worst < 0.01, worst
    assert unresolved and all(float(t) > 80 for t in unresolved), r.stderr
    r = run(["export", "iso0.6.h5", "--format", "rgl", "--side", "transmission", "-o", "t.bsdf"], expect=2)
    assert "reflection only" in r.stderr, r.stderr
    listed = os.path.join(TMP, "listed.toml")
    with open(os.path.join(TMP, "aniso.toml")) as f:
        text = f.read().replace('incidence = "all"', "incidence = [[10.0, 0.0], [40.0, 30.0]]")
    with open(listed, "w") as f:
        f.write(text.replace('"aniso.h5"', '"listed.h5"'))
    run(["run", listed, "-o", "listed.h5"], mpi=2)
    r = run(["export", "listed.h5", "--format", "rgl", "-o", "listed.bsdf"], expect=2)
    assert "incidence = \"all\"" in r.stderr, r.stderr
    assert not os.path.exists(os.path.join(TMP, "t.bsdf")) and not os.path.exists(os.path.join(TMP, "listed.bsdf"))
    print("refused with exit 2, nothing written: --side transmission; an anisotropic table of listed incidences")


def test_export_mbsdf():
    """`export --format mbsdf` read back by a reader that does what the MDL SDK's runtime does
    (mbsdf_reader.py: the SDK loader's block and byte-count checks, the runtime's cell-centred
    trilinear lookup of the symmetrised data, its row albedos and the factor it puts on all light
    where the largest exceeds 1). At random pairs per table:
    - a statistical GGX mirror (alpha 0.6, 24 x 48 bins): stored symmetric; at the file's own nodes
      the table's reciprocal mean (f(i,o) + f(o,i)) / 2 times d(ti) d(to), one factor per pair of
      rows at every azimuth, within the printed figure; between them, in the lobe, as the runtime sees
      it against `eval` and against the table's reciprocal mean: median relative difference within
      2.5 %, 90th percentile within 6 %; the runtime's albedo per incidence cell within 1 % of the
      table's (interpolated in theta between its rings);
    - a rough BK7 surface (GGX 0.3, both sides): the transmission stored symmetric and balanced as
      above; the runtime dims nothing (factor 1) and its albedo on both sides is the table's within
      1 % at every 4th incidence cell; the printed L1 of what that changes in the BTDF's lobe equals
      the reader's own, with a warning;
    - an anisotropic table: the warning with the anisotropy lost, and the file holding the reciprocal
      mean of the mean over the table's incidence azimuths of `eval` (times d(ti) d(to));
    - an anisotropic table of listed incidences at two azimuths: refused (no azimuthal mean);
    - an isotropic surface the run cannot reduce (disk grid, listed incidences): isotropic in the file.
    One scalar file per wavelength; --colour rgb writes one RGB file."""
    sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
    from mbsdf_reader import Mbsdf
    jobs = {"ggx": ('alpha = 0.6', 'name = "mirror"', "[550.0]", 24, 48, '["coherent"]', 200000),
            "glass": ('alpha = 0.3', 'kind = "dielectric"\nname = "BK7"', "[500.0, 600.0]", 18, 36,
                      '["coherent", "multiple"]', 50000),
            "aniso": ('alpha = [0.25, 0.6]', 'name = "mirror"', "[550.0]", 12, 24, '["coherent"]', 20000)}
    for name, (alpha, material, nm, n_theta, n_phi, components, paths) in jobs.items():
        with open(os.path.join(TMP, f"{name}.toml"), "w") as f:
            f.write(f"""[geometry]\nkind = "statistical"\nndf = "ggx"\n{alpha}\n[material]\n{material}
[spectrum]\nwavelengths_nm = {nm}\n[directions]\nn_theta = {n_theta}\nn_phi = {n_phi}\nincidence = "all"
[effects]\ncomponents = {components}\n[sampling]\npaths_per_slice = {paths}\nseed = 5\n[output]\npath = "{name}.h5"\n""")
        run(["run", f"{name}.toml", "-o", f"{name}.h5"], mpi=2)
    rng = np.random.default_rng(23)

    def random_rows(n):
        c = np.cos(np.radians(80))
        return [(np.degrees(np.arccos(rng.uniform(c, 1))), rng.uniform(0, 360),
                 np.degrees(np.arccos(rng.uniform(c, 1))), rng.uniform(0, 360)) for _ in range(n)]

    def table_values(h5name, rows, transmitted, column=0):
        with open(os.path.join(TMP, "pairs.txt"), "w") as f:
            f.write("\n".join(f"{a},{b},{180 - c if transmitted else c},{d}" for a, b, c, d in rows) + "\n")
        out = run(["eval", h5name, "--pairs", "pairs.txt"]).stdout.splitlines()[2:]
        return np.array([float(line.split(",")[4 + column]) for line in out])

    def file_values(m, part, rows, symmetrise):
        return np.array([m.eval(part, *np.radians(r), symmetrise=symmetrise)[0] for r in rows])

    def table_albedo(h5name, theta_deg, upper):
        """The table's sum f * projected solid angle on one side, linear in theta between its rings."""
        with h5py.File(os.path.join(TMP, h5name), "r") as h:
            op = h["/grid/projected_solid_angle"][:]
            nh = len(op) // 2
            th = h["/incidence/theta_deg"][:]
            total = sum(h["/bsdf/" + c][:, 0, :].astype(float) for c in h["/bsdf"].keys()
                        if c in ("coherent", "incoherent", "multiple"))
        sides = slice(0, nh) if upper else slice(nh, 2 * nh)
        rings = sorted({t for t in th if t < 90})
        per_ring = [np.mean([np.sum(total[i, sides] * op[sides]) for i in np.where(th == t)[0]]) for t in rings]
        return float(np.interp(theta_deg, rings, per_ring))

    def runtime_albedo_error(m, h5name, part, rows=(2, 12, 22, 32)):
        """Largest relative difference between the albedo an MDL runtime gives incidence cell k (the
        symmetrised data's row sum, times the factor it puts on all light) and the table's."""
        scale = m.runtime_scale()
        return max(abs(scale * m.albedo(part, k)[0] / table_albedo(h5name, (k + 0.5) * 2.0, part == "reflection") - 1)
                   for k in rows)

    def check_symmetric_balance(m, part, h5name, transmitted, printed=None, ks=(1, 15, 30, 40)):
        """The part is stored symmetric, and at its nodes it is d(ti) d(to) times the table's
        reciprocal mean (f(ti,to) + f(to,ti)) / 2: one factor per (ti, to) at every azimuth; for a
        reciprocal table, within `printed` (the runtime albedo error balancing removed) of 1."""
        d = m.table(part, False)
        assert np.array_equal(d, d.transpose(1, 0, 2, 3)), f"{part} is not stored symmetric"
        worst = 0.0
        for k in ks:
            for to in rng.integers(0, d.shape[0], 4):
                ps = rng.integers(0, d.shape[2], 6)
                cells = [((k + 0.5) * 2.0, 0.0, (to + 0.5) * 2.0, (p + 0.5) * 2.0) for p in ps]
                back = [((to + 0.5) * 2.0, 0.0, (k + 0.5) * 2.0, (p + 0.5) * 2.0) for p in ps]
                mean = 0.5 * (table_values(h5name, cells, transmitted) + table_values(h5name, back, transmitted))
                ratio = d[k, to, ps, 0] / mean
                assert np.ptp(ratio) < 1e-5 * np.mean(ratio), (part, k, to, ratio)
                worst = max(worst, abs(np.mean(ratio) - 1))
        assert printed is None or worst <= printed + 0.005, (part, worst, printed)
        return worst

    # The GGX mirror, as a runtime sees it.
    r = run(["export", "ggx.h5", "--format", "mbsdf", "-o", "ggx.mbsdf"])
    assert "warning" not in r.stderr, r.stderr
    m = Mbsdf(os.path.join(TMP, "ggx.mbsdf"))
    assert list(m.parts) == ["reflection"] and m.metadata["WAVELENGTH_NM"] == "550", (m.parts.keys(), m.metadata)
    # At the file's own nodes (cell centres): placement, order and azimuth sense, and the printed
    # figure of what balancing changed.
    correction = float(re.search(r"would have been off by ([0-9.]+) %", r.stderr).group(1)) / 100
    worst_node = check_symmetric_balance(m, "reflection", "ggx.h5", False, correction)
    # Between nodes, in the lobe (f above a quarter of its peak, where the table's noise is small): as
    # the runtime sees it against the table, and against the table's reciprocal mean (the two differ
    # by the table's noise, which the mean halves).
    rows = random_rows(1500)
    table = table_values("ggx.h5", rows, False)
    table_back = table_values("ggx.h5", [(c, d, a, b) for a, b, c, d in rows], False)
    lobe = table > 0.25 * table.max()
    rows, table, table_back = [r for r, k in zip(rows, lobe) if k], table[lobe], table_back[lobe]
    seen = file_values(m, "reflection", rows, True)
    stored, rel = np.abs(seen / table - 1), np.abs(seen / (0.5 * (table + table_back)) - 1)
    worst_albedo = runtime_albedo_error(m, "ggx.h5", "reflection")
    print(f"GGX 0.6: {os.path.getsize(os.path.join(TMP, 'ggx.mbsdf')) / 1e6:.2f} MB; at the file's nodes: the "
          f"table's reciprocal mean times d(ti) d(to), up to {worst_node:.2%} (printed {correction:.2%}); in the lobe "
          f"({len(rows)} pairs) vs eval: median {np.median(stored):.2%}, p90 {np.percentile(stored, 90):.2%}; vs "
          f"the table's reciprocal mean: median {np.median(rel):.2%}, p90 {np.percentile(rel, 90):.2%}; the "
          f"runtime's albedo vs the table's: worst {worst_albedo:.2%}")
    for x in (stored, rel):
        assert np.median(x) < 0.025 and np.percentile(x, 90) < 0.06, (np.median(x), np.percentile(x, 90))
    assert worst_albedo < 0.01, worst_albedo
    # Glass: both sides. A symmetrising runtime reads the file as stored: its transmitted albedo is
    # the table's from every incidence and it dims nothing; the figure printed for what the
    # symmetric file changes in the BTDF's lobe is the reader's own.
    r = run(["export", "glass.h5", "--format", "mbsdf", "-o", "glass.mbsdf"])
    assert os.path.exists(os.path.join(TMP, "glass_500nm.mbsdf")) and os.path.exists(os.path.join(TMP, "glass_600nm.mbsdf"))
    m = Mbsdf(os.path.join(TMP, "glass_500nm.mbsdf"))
    assert list(m.parts) == ["reflection", "transmission"], m.parts.keys()
    before = float(re.search(r"a runtime would have been off by ([0-9.]+) %", r.stderr).group(1)) / 100
    check_symmetric_balance(m, "transmission", "glass.h5", True, ks=(3, 20, 35))
    worst_albedo = max(runtime_albedo_error(m, "glass.h5", part, range(0, 45, 4)) for part in m.parts)
    d = m.table("transmission", False)
    n = d.shape[0]
    centre = (np.arange(n) + 0.5) * 2.0
    cells = [(ti, 0.0, to, (p + 0.5) * 2.0) for ti in centre for to in centre for p in range(d.shape[2])]
    computed = table_values("glass.h5", cells, True).reshape(d.shape[:3])
    weight = (np.cos(np.radians(centre)) * np.sin(np.radians(centre)))[None, :, None]
    change = float(np.sum(np.abs(d[..., 0] - np.maximum(computed, 0)) * weight) / np.sum(np.abs(computed) * weight))
    printed = float(re.search(r"differs from the table's by ([0-9.]+) %", r.stderr).group(1)) / 100
    print(f"BK7: runtime factor on all light {m.runtime_scale():.4f}; the runtime's albedo vs the table's, both sides, "
          f"every 4th incidence cell: worst {worst_albedo:.2%}; a runtime would have been off by {before:.1%}; the "
          f"BTDF's lobe in the file vs the table's: L1 {change:.1%} (printed {printed:.1%})")
    assert m.runtime_scale() == 1.0 and worst_albedo < 0.01, (m.runtime_scale(), worst_albedo)
    assert abs(change - printed) < 0.005 and "warning: transmission stored symmetric" in r.stderr, (change, printed)
    run(["export", "glass.h5", "--format", "mbsdf", "--colour", "rgb", "-o", "glass-rgb.mbsdf"])
    c = Mbsdf(os.path.join(TMP, "glass-rgb.mbsdf"))
    assert c.parts["transmission"].shape[3] == 3 and c.metadata["COLOUR"] == "linear sRGB", c.metadata
    # Anisotropic: a quantified warning, and the mean over the incidence azimuths in the file.
    r = run(["export", "aniso.h5", "--format", "mbsdf", "-o", "aniso.mbsdf"])
    lost = float(re.search(r"anisotropic; .* ([0-9.]+) % of the table", r.stderr).group(1))
    m = Mbsdf(os.path.join(TMP, "aniso.mbsdf"))
    d = m.table("reflection", False)
    correction = float(re.search(r"would have been off by ([0-9.]+) %", r.stderr).group(1)) / 100
    azimuths = (np.arange(24) + 0.5) * 15.0
    ratios = []
    for to in rng.integers(0, d.shape[0], 6):
        t_o = (to + 0.5) * 2.0
        per_p = []
        for p in rng.integers(0, d.shape[2], 2):
            dphi = (p + 0.5) * 2.0
            there = np.mean(table_values("aniso.h5", [(21.0, a, t_o, (a + dphi) % 360) for a in azimuths], False))
            back = np.mean(table_values("aniso.h5", [(t_o, a, 21.0, (a + dphi) % 360) for a in azimuths], False))
            per_p.append(d[10, to, p, 0] / (0.5 * (there + back)))
        assert abs(per_p[0] - per_p[1]) < 1e-5 * per_p[0], (to, per_p)
        ratios += per_p
    print(f"anisotropic GGX (0.25, 0.6): warned of {lost} % lost; the file holds the reciprocal mean of the azimuthal "
          f"mean of eval times d(ti) d(to) on its 21 deg row, {min(ratios):.4f}-{max(ratios):.4f} (printed "
          f"{correction:.2%})")
    assert max(abs(x - 1) for x in ratios) <= correction + 0.005, ratios
    # Listed incidences of an anisotropic table at several azimuths give no azimuthal mean: refused.
    with open(os.path.join(TMP, "aniso.toml")) as f:
        text_listed = f.read().replace('incidence = "all"', "incidence = [[10.0, 0.0], [40.0, 30.0]]")
    with open(os.path.join(TMP, "listed.toml"), "w") as f:
        f.write(text_listed.replace('"aniso.h5"', '"listed.h5"'))
    run(["run", "listed.toml", "-o", "listed.h5"], mpi=2)
    r = run(["export", "listed.h5", "--format", "mbsdf", "-o", "listed.mbsdf"], expect=2)
    assert "lists incidences at 2 azimuths" in r.stderr and not os.path.exists(os.path.join(TMP, "listed.mbsdf")), r.stderr
    # An isotropic surface the run cannot reduce (disk grid, listed incidences) is still isotropic for
    # the exporters: one azimuth, no anisotropy warning.
    with open(os.path.join(TMP, "disk.toml"), "w") as f:
        f.write("""[geometry]\nkind = "statistical"\nndf = "ggx"\nalpha = 0.4\n[material]\nname = "Au"
[spectrum]\nwavelengths_nm = [550.0]\n[directions]\ngrid = "disk"\nwidth = 17\nheight = 17
incidence = [[0.0, 0.0], [30.0, 0.0], [60.0, 0.0]]\n[effects]\ncomponents = ["coherent", "multiple"]
[sampling]\npaths_per_slice = 10000\nseed = 3\n[output]\npath = "disk.h5"\n""")
    run(["run", "disk.toml", "-o", "disk.h5"], mpi=2)
    with h5py.File(os.path.join(TMP, "disk.h5"), "r") as h:
        symmetry = h.attrs["symmetry"]
        symmetry = symmetry.decode() if isinstance(symmetry, bytes) else str(symmetry)
        assert symmetry.startswith("isotropic"), symmetry
    r = run(["export", "disk.h5", "--format", "mbsdf", "-o", "disk.mbsdf"])
    assert "anisotropic" not in r.stderr, r.stderr
    print("isotropic surface on a disk grid, listed incidences: exported as isotropic, no warning")
    assert lost > 5, r.stderr


def fresnel_unpolarised(cos_i, eta):
    """Fresnel reflectance of unpolarised light at a smooth interface, eta = n_t / n_i (1 beyond the
    critical angle)."""
    sin_t2 = (1 - cos_i ** 2) / eta ** 2
    if sin_t2 >= 1:
        return 1.0
    cos_t = np.sqrt(1 - sin_t2)
    rs = (cos_i - eta * cos_t) / (cos_i + eta * cos_t)
    rp = (eta * cos_i - cos_t) / (eta * cos_i + cos_t)
    return 0.5 * (rs * rs + rp * rp)


def test_defaults_closed_form():
    """A flat mirror and flat glass (n 1.5, lit from above and from inside) with every sampling key at
    its default, incidence bin-averaged and exact: the wave estimator the job gets is deterministic
    (the log says which and why), and the table's reflectance and transmittance are the Fresnel
    closed form (bin-averaged: the mean over the incidence bin) within 1 % of the incident energy;
    at exact incidence the reflectance within 2 % of itself. Monte Carlo with 256 samples per bin
    gave the mirror an albedo of -11 +- 4."""
    cases = (("mirror", 'name = "mirror"', [[30.0, 0.0], [61.9, 0.0]]),
             ("glass", 'kind = "dielectric"\nior = 1.5', [[30.0, 0.0], [61.9, 0.0], [150.0, 0.0], [125.0, 0.0]]))
    for name, material, incidence in cases:
        for sampling in ("bin", "exact"):
            job = os.path.join(TMP, f"flat-{name}-{sampling}.toml")
            with open(job, "w") as f:
                f.write(f"""[geometry]\nkind = "flat"\n[material]\n{material}\n[spectrum]\nwavelengths_nm = [550.0]
[directions]\nn_theta = 8\nn_phi = 16\nincidence = {incidence}\nincidence_sampling = "{sampling}"
[effects]\ncomponents = ["coherent", "incoherent"]\n""")
            out = f"flat-{name}-{sampling}.h5"
            r = run(["run", job, "-o", out])
            line = next(x for x in r.stderr.splitlines() + r.stdout.splitlines() if "scalar diffraction:" in x)
            assert "exact estimator (chosen as deterministic" in line, line
            with h5py.File(os.path.join(TMP, out), "r") as h:
                op = h["/grid/projected_solid_angle"][:]
                nh = len(op) // 2
                total = sum(h["/bsdf/" + c][:, 0, :].astype(float) for c in ("coherent", "incoherent"))
                upper, lower = total[:, :nh] @ op[:nh], total[:, nh:] @ op[nh:]
                th = h["/incidence/theta_deg"][:]
            for k, (theta, _) in enumerate(incidence):
                above = theta < 90
                eta = 1.0 if name == "mirror" else (1.5 if above else 1 / 1.5)
                cos_i = abs(np.cos(np.radians(theta)))
                if sampling == "bin":  # the bin's incidences, uniform in projected solid angle
                    width = 90.0 / 8
                    lo = np.floor(min(theta, 180 - theta) / width) * width
                    mu = np.sqrt(np.linspace(np.cos(np.radians(lo + width)) ** 2, np.cos(np.radians(lo)) ** 2, 2001))
                    want_r = float(np.mean([fresnel_unpolarised(m, eta) for m in mu]))
                else:
                    want_r = fresnel_unpolarised(cos_i, eta)
                want_r = 1.0 if name == "mirror" else want_r
                got_r, got_t = (upper[k], lower[k]) if above else (lower[k], upper[k])
                print(f"flat {name}, {sampling} incidence at {th[k]:.1f} deg: R {got_r:.5f} (Fresnel {want_r:.5f}), "
                      f"T {got_t:.5f} ({1 - want_r:.5f})")
                assert abs(got_r - want_r) < 0.01 and abs(got_t - (1 - want_r)) < 0.01, (name, sampling, theta, got_r,
                                                                                         got_t, want_r)
                if sampling == "exact":
                    assert abs(got_r / want_r - 1) < 0.02, (name, theta, got_r, want_r)


def caveat_texts(job, out, attribute):
    """What `check`, the run's log and `info` print for `job`, and the table's root attribute."""
    texts = {"check": run(["check", job]).stdout}
    r = run(["run", job, "-o", out])
    texts["run"] = r.stdout + r.stderr
    texts["info"] = run(["info", out]).stdout
    with h5py.File(os.path.join(TMP, out), "r") as h:
        attr = h.attrs.get(attribute)
    return texts, attr.decode() if isinstance(attr, bytes) else attr


def test_scalar_model_caveat():
    """A periodic structure the rigorous validity map places beyond the tolerance (oblique light on a
    glass grating, a metal grating past the validated angles) is said by check, the run (start and
    summary), the file's `scalar_model` attribute and info, with the map's figure; one the map
    vouches for says nothing of it."""
    cases = [("glass-50", 'kind = "dielectric"\nior = 1.5', 50.0, 0.25, "off by up to"),
             ("al-70", 'name = "Al"', 70.0, 0.05, "error here is unknown"),
             ("glass-0", 'kind = "dielectric"\nior = 1.5', 0.0, 0.1, None)]
    for name, material, theta, depth, says in cases:
        job = os.path.join(TMP, f"sm-{name}.toml")
        with open(job, "w") as f:
            f.write(f"""[geometry]\nkind = "binary-grating"\nperiod_um = 5.0\ndepth_um = {depth}\nduty = 0.5
size_um = [5.0, 0.2]\n[material]\n{material}\n[spectrum]\nwavelengths_nm = [500.0]
[directions]\nn_theta = 90\nn_phi = 4\nincidence = [[{theta}, 0.0]]\nincidence_sampling = "exact"
[scene]\ncoherence_length_um = 50.0\n[effects]\ncomponents = ["coherent", "incoherent"]
[sampling]\npaths_per_slice = 2000\nwave_estimator = "exact"\n""")
        texts, attr = caveat_texts(job, f"sm-{name}.h5", "scalar_model")
        if says:
            for where, text in texts.items():
                assert "scalar model:" in text and says in text, f"{name}: '{says}' not in `{where}`:\n{text}"
            warned = [x for x in texts["run"].splitlines() if "scalar model:" in x and "warn" in x]
            assert len(warned) >= 2, f"{name}: not a warning at the start and in the summary:\n{texts['run']}"
            assert attr is not None and says in attr, attr
            m = re.search(r"off by up to ([0-9.]+)", attr)
            assert m is None or float(m.group(1)) > 0.01, attr
        else:
            assert attr is None, f"{name}: scalar_model = {attr}"
            assert not [x for x in texts["run"].splitlines() if "scalar model:" in x and "warn" in x], texts["run"]
            assert "WARNING" not in texts["info"] and "WARNING" not in texts["check"], texts
    print("scalar model beyond the tolerance: said by check, the run (start and summary), the file and info; "
          "a grating the map vouches for: silent")


def test_wave_errors_caveat():
    """Where the wave term's stored errors are not vouched for (`paper`'s bias estimate), `check`, the
    run's log (at the start and in the closing summary), the file's `wave_errors` attribute and `info`
    say so; `area` (collimated or over incidence bins), and `orders` or a deterministic estimator over
    incidence bins, whose errors hold against `exact`, say nothing."""
    cases = (("area-bin", "area", "bin", None), ("paper-bin", "paper", "bin", "bias estimate"),
             ("area-exact", "area", "exact", None), ("exact-bin", "exact", "bin", None),
             ("orders-bin", "orders", "bin", None))
    for name, estimator, sampling, says in cases:
        job = os.path.join(TMP, f"we-{name}.toml")
        with open(job, "w") as f:
            f.write(f"""[geometry]\nkind = "sine-grating"\nperiod_um = 4.0\namplitude_um = 0.02\nsize_um = [4.0, 4.0]
[material]\nname = "Al"\n[spectrum]\nwavelengths_nm = [550.0]
[directions]\nn_theta = 6\nn_phi = 12\nincidence = [[20.0, 10.0]]\nincidence_sampling = "{sampling}"
[effects]\ncomponents = ["coherent", "incoherent"]\n[sampling]\nwave_estimator = "{estimator}"
wave_samples_per_bin = 64\n""")
        texts, attr = caveat_texts(job, f"we-{name}.h5", "wave_errors")
        if says:
            for where, text in texts.items():
                assert says in text, f"{name}: '{says}' not in `{where}`:\n{text}"
            assert texts["run"].count(says) >= 2, f"{name}: the closing summary does not repeat it:\n{texts['run']}"
            assert attr is not None and says in attr, attr
        else:
            for where, text in texts.items():
                assert "not vouched" not in text and "bias estimate" not in text, f"{name}: `{where}` warns:\n{text}"
            assert attr is None, f"{name}: wave_errors = {attr}"
    print("wave errors not vouched for: said by check, the run (start and summary), the file and info; "
          "area, orders and exact: silent")


def test_nonphysical_flags():
    """Every slice the model cannot vouch for is flagged (/stats/nonphysical, a WARN naming the slice
    and figure, the run's closing count, `info`, `report`), and no physical one is: 100 um deep mirror trenches
    with max_depth 4 (half the paths truncated: 8), a glass binary grating of period 4 lambda and
    depth 2 lambda (scalar energy 1.136: 2 | 4), a flat mirror at 80 deg under a 50 um window (the
    windowed Kirchhoff lobe loses 0.021 below the horizon: 4); against a flat mirror at 30 and 60 deg
    and flat glass from above and inside, a shallow sine grating, a statistical GGX gold surface
    (none)."""
    grating = 'kind = "binary-grating"\nperiod_um = 2.0\n'
    flat = 'kind = "flat"\n'
    cases = (  # name, geometry, material, wavelength, incidence, components, extra sampling, flags expected
        ("trench", grating + 'depth_um = 100.0\nsize_um = [4.0, 4.0]\n', 'name = "mirror"', 550.0, "[[10.0, 0.0]]",
         '["coherent", "multiple"]', "paths_per_slice = 20000\nmax_depth = 4\n", 8),
        ("deep-glass", grating + 'depth_um = 1.0\n', 'kind = "dielectric"\nior = 1.5', 500.0, "[[0.0, 0.0]]",
         '["coherent", "incoherent"]', "", 2 | 4),
        ("grazing-mirror", flat, 'name = "mirror"', 550.0, "[[80.0, 0.0]]", '["coherent", "incoherent"]', "", 4),
        ("flat-mirror", flat, 'name = "mirror"', 550.0, "[[30.0, 0.0], [60.0, 0.0]]", '["coherent", "incoherent"]',
         "", 0),
        ("flat-glass", flat, 'kind = "dielectric"\nior = 1.5', 550.0, "[[30.0, 0.0], [150.0, 0.0], [135.0, 0.0]]",
         '["coherent", "incoherent"]', "", 0),
        ("sine", 'kind = "sine-grating"\nperiod_um = 5.0\namplitude_um = 0.02\n', 'name = "Al"', 550.0,
         "[[0.0, 0.0], [40.0, 0.0]]", '["coherent", "incoherent", "multiple"]', "paths_per_slice = 20000\n", 0),
        ("ggx-gold", 'kind = "statistical"\nndf = "ggx"\nalpha = 0.5\n', 'kind = "conductor"\nname = "Au"', 550.0,
         "[[0.0, 0.0], [45.0, 0.0], [85.0, 0.0]]", '["coherent", "multiple"]', "paths_per_slice = 20000\n", 0))
    for name, geometry, material, nm, incidence, components, sampling, want in cases:
        job = os.path.join(TMP, f"np-{name}.toml")
        with open(job, "w") as f:
            f.write(f"""[geometry]\n{geometry}[material]\n{material}\n[spectrum]\nwavelengths_nm = [{nm}]
[directions]\nn_theta = 8\nn_phi = 16\nincidence = {incidence}\nincidence_sampling = "exact"
[effects]\ncomponents = {components}\n[sampling]\nseed = 3\n{sampling}""")
        r = run(["run", job, "-o", f"np-{name}.h5"])
        with h5py.File(os.path.join(TMP, f"np-{name}.h5"), "r") as h:
            flags = h["/stats/nonphysical"][:, :, 0].astype(int)
        got = int(np.bitwise_or.reduce(flags.reshape(-1)))
        info = run(["info", f"np-{name}.h5"]).stdout
        warned = [x for x in r.stderr.splitlines() if "is not physical" in x]
        print(f"{name}: flags {flags.reshape(-1).tolist()} (want {want}); {len(warned)} warning(s)")
        assert got == want, (name, flags, want)
        if want:
            assert warned and f"slice {int(np.argmax(flags.max(axis=1) > 0))} " in warned[0], (name, r.stderr)
            assert "slice(s) computed now are not physical" in r.stderr, r.stderr
            assert "not physical: " in info, info
            run(["report", f"np-{name}.h5", "--render-size", "16", "-o", f"np-{name}.html"])
            with open(os.path.join(TMP, f"np-{name}.html")) as f:
                assert 'class="flagged">' in f.read(), name
        else:
            assert not warned and "not physical" not in info, (name, warned, info)


def test_effects_adversarial():
    """Scenes built to fool the effects planner's pilots: an inter-reflection threshold between pilot
    incidences, listed incidences, collimated against bin-averaged incidence on a grating lit along
    its grooves, anisotropic grooves lit across and along, a rough surface at the wave pilot's noise
    floor (decided from the Kirchhoff ensemble), a dielectric grating lit from inside, and a smooth
    noisy gold whose diffraction the ensemble turns off without pilots or per-tile checks. For each, per slice and wavelength, the auto
    table is within the tolerance of the full table's WM model beyond noise (wm_excess_beyond_noise),
    and auto's tiles do no more work than the full table's (ray casts and wave samples, the
    machine-independent measure of `/stats/rays` and `/stats/wave_samples`) x 1.05; the pilots' own
    work is bounded by [effects] pilot_budget (asserted from the plan the file records)."""
    vgroove = 'kind = "ridged"\nsize_um = [2.0, 0.3]\nperiod_um = 2.0\napex_angle_deg = 125.0'
    binary = 'kind = "binary-grating"\nsize_um = [2.0, 0.3]\nperiod_um = 2.0\ndepth_um = 1.0\nduty = 0.5'
    sine = 'kind = "sine-grating"\nsize_um = [2.0, 0.3]\nperiod_um = 2.0\namplitude_um = 0.4'
    glass = 'kind = "dielectric"\nior = 1.5'
    along = "[[20.0, 90.0], [40.0, 90.0], [60.0, 90.0]]"
    scenes = {
        "V-groove, every incidence (a threshold at 7.5-20 deg between pilots)":
            (vgroove, 'name = "mirror"', "coherence_length_um = 50.0\nincidence_max_deg = 70.0", '"all"', ""),
        "V-groove, five listed incidences":
            (vgroove, 'name = "mirror"', "coherence_length_um = 50.0",
             "[[0.0, 0.0], [20.0, 0.0], [25.0, 90.0], [30.0, 90.0], [32.0, 90.0]]", ""),
        "binary grating lit along its grooves, collimated":
            (binary, 'name = "mirror"', "coherence_length_um = 50.0", along, 'incidence_sampling = "exact"'),
        "binary grating lit along its grooves, bin-averaged": (binary, 'name = "mirror"', "coherence_length_um = 50.0", along, ""),
        "anisotropic sine grating, across and along":
            (sine, 'name = "Al"', "coherence_length_um = 50.0",
             "[[30.0, 0.0], [30.0, 90.0], [60.0, 0.0], [60.0, 90.0], [10.0, 45.0]]", ""),
        "rough Al at the wave pilot's noise floor":
            ('kind = "gaussian"\nsize_um = [20.0, 20.0]\nrms_um = 0.3\ncorrelation_um = 2.0', 'name = "Al"', 'light = "sun"',
             "[[0.0, 0.0], [40.0, 0.0], [70.0, 30.0]]", ""),
        "glass sine grating lit from inside":
            (sine, glass, "coherence_length_um = 50.0", "[[130.0, 45.0], [150.0, 0.0], [170.0, 90.0]]", ""),
        # Off from physics, with no pilot and no per-tile check: the Kirchhoff ensemble's bound.
        "gold with 1 nm ground noise, collimated, its lobes inside their bins":
            ('kind = "flat"\nsize_um = [5.0, 5.0]\nground_noise_rms_nm = 1.0', 'name = "Au"',
             "coherence_length_um = 2000.0", "[[39.375, 11.25], [50.625, 101.25], [61.875, 191.25]]",
             'incidence_sampling = "exact"'),
    }
    for k, (name, (geo, mat, scene, incidence, directions)) in enumerate(scenes.items()):
        auto = effects_job(os.path.join(TMP, f"adv-auto{k}.toml"), geo, mat, scene, incidence=incidence, directions=directions)
        full = effects_job(os.path.join(TMP, f"adv-full{k}.toml"), geo, mat, scene, ["coherent", "incoherent", "multiple"],
                           incidence=incidence, directions=directions)
        run(["run", auto, "-o", f"adv-auto{k}.h5"], mpi=2)
        run(["run", full, "-o", f"adv-full{k}.h5"], mpi=2)
        with h5py.File(os.path.join(TMP, f"adv-auto{k}.h5"), "r") as a, \
                h5py.File(os.path.join(TMP, f"adv-full{k}.h5"), "r") as b:
            plan = json.loads(a.attrs["effects_plan"])
            tol = plan["tolerance"]
            worst = max(wm_excess_beyond_noise(a, b))
            assert worst <= tol, f"{name}: auto differs from the full table by {worst:.4f} beyond noise (tolerance {tol})"
            budget = plan["pilot_budget"]
            assert budget["path_tiles_spent"] <= budget["tiles"] + 1e-9 and budget["wave_tiles_spent"] <= budget["tiles"] + 1e-9, budget
            # Symmetry-copied slices repeat their tile's work: count each computed tile once.
            rays = [float(np.sum(np.unique(f["/stats/rays"][:]))) for f in (a, b)]
            samples = [float(np.sum(f["/stats/wave_samples"][:])) for f in (a, b)]
            assert rays[0] <= 1.05 * rays[1], f"{name}: auto's tiles cast {rays[0]:.3g} rays, the full table's {rays[1]:.3g}"
            same_estimator = a.attrs.get("wave_estimator") == b.attrs.get("wave_estimator")
            if same_estimator:
                assert samples[0] <= 1.05 * samples[1], f"{name}: wave samples {samples[0]:.3g} against {samples[1]:.3g}"
            reenabled = int(np.sum(a["/stats/multiple_reenabled"][:])) if "/stats/multiple_reenabled" in a else 0
            diffraction = next(d for d in plan["decisions"] if d["effect"] == "incoherent")
            if "\"gaussian\"" in geo or "ground_noise" in geo:
                # Random rough surfaces are decided from physics: no wave pilot.
                assert diffraction.get("decided_by") == "kirchhoff ensemble", diffraction
                assert budget["wave_tiles_spent"] == 0, budget
            if "ground_noise" in geo:
                assert not diffraction["on"] and "incoherent" not in a["bsdf"], diffraction
        print(f"{name}: auto = {sorted(plan['components'])}, |auto - full| beyond noise {max(worst, 0):.4f} <= {tol}; "
              f"rays {rays[0]:.3g} vs {rays[1]:.3g} ({rays[0] / max(rays[1], 1):.2f}x), wave samples {samples[0]:.3g} vs "
              f"{samples[1]:.3g}{'' if same_estimator else ' (another estimator)'}; pilots {budget['path_tiles_spent']:.2f} + "
              f"{budget['wave_tiles_spent']:.2f} of {budget['tiles']:.2f} tiles; multiple re-enabled on {reenabled} slice(s)")


def test_tour():
    """The README's five-minute tour runs top to bottom, line by line, from a copy of the
    repository's layout (build/, jobs/, scripts/ linked), every line with exit status 0."""
    with open(os.path.join(SRC, "README.md")) as f:
        readme = f.read()
    section = readme.split("## A five-minute tour", 1)[1].split("\n## ", 1)[0]
    block = section.split("```sh\n", 1)[1].split("```", 1)[0]
    lines = [l for l in block.splitlines() if l.strip() and not l.lstrip().startswith("#")]
    assert len(lines) >= 8, lines
    root = os.path.join(TMP, "tour")
    os.makedirs(root)
    for name, target in (("build", BUILD), ("jobs", os.path.join(SRC, "jobs")), ("scripts", os.path.join(SRC, "scripts"))):
        os.symlink(target, os.path.join(root, name))
    for line in lines:
        p = subprocess.run(["bash", "-c", line], capture_output=True, text=True, timeout=600, env=MPI_ENV, cwd=root)
        assert p.returncode == 0, f"{line}\nexit {p.returncode}\n{p.stdout[-3000:]}\n{p.stderr[-3000:]}"
    made = sorted(os.listdir(os.path.join(root, "out")))
    print(f"README tour: {len(lines)} lines ran in order; out/ holds {', '.join(made)}")


def test_diff():
    """`diff`: a table against itself differs by nothing; two seeds of one job differ by noise only
    (each component's chi-square z-score and energies' z within 5, and |mean z² − 1| small); a designed
    surface against its produced variant ([geometry.defects]: depth −10 %, edges rounded) differs
    beyond noise; tables on different grids are refused; the reports (.json, .csv, .png) are written."""
    raster = '[geometry.defects]\ntexel_um = 0.05\n'
    hemis = 'kind = "hemispheres"\nsize_um = [10.0, 10.0]\nradius_um = 2.0\nspacing_um = 5.0\nresolution_um = 0.25\n'
    designed = small_job(os.path.join(TMP, "designed.toml"), output="designed.h5", geometry=hemis + raster)
    produced = small_job(os.path.join(TMP, "produced.toml"), output="produced.h5",
                         geometry=hemis + raster + "depth_scale = 0.9\nedge_radius_um = 0.15\n")
    seed2 = small_job(os.path.join(TMP, "seed2.toml"), output="seed2.h5", geometry=hemis + raster)
    text = open(seed2).read().replace("seed = 7", "seed = 8")
    open(seed2, "w").write(text)
    for job in (designed, produced, seed2):
        run(["run", job], mpi=2, timeout=600)
    same = run(["diff", "designed.h5", "designed.h5", "-o", "same.json"]).stdout
    assert "0 of 5 slices differ beyond noise" in same, same
    j = json.load(open(os.path.join(TMP, "same.json")))
    assert not j["beyond_noise"]
    for s in j["slices"]:
        for name, c in s["components"].items():
            assert c["l1"] == 0 and c["chi2_z"] < 0, (name, c)
        assert s["delta_e00_reflected"] == 0 and s["lobe"]["shift_deg"] == 0, s
    seeds = run(["diff", "designed.h5", "seed2.h5", "-o", "seeds.json"]).stdout
    j = json.load(open(os.path.join(TMP, "seeds.json")))
    assert not j["beyond_noise"], seeds
    for s in j["slices"]:
        for name, c in s["components"].items():
            assert c["chi2_z"] < 5 and max(abs(z) for z in c["energy_z"]) < 5, (s["theta_i_deg"], name, c)
            assert c["l1"] > 0, (name, c)
    print("two seeds:", seeds.strip().splitlines()[-2])
    dp = run(["diff", "designed.h5", "produced.h5", "-o", "dp.json"]).stdout
    j = json.load(open(os.path.join(TMP, "dp.json")))
    assert j["beyond_noise"], dp
    beyond = sum(any(c["beyond_noise"] for c in s["components"].values()) for s in j["slices"])
    assert beyond >= 4, dp
    print("designed vs produced:", dp.strip().splitlines()[-2])
    run(["diff", "designed.h5", "produced.h5", "-o", "dp.csv"])
    rows = open(os.path.join(TMP, "dp.csv")).read().strip().splitlines()
    assert rows[0].startswith("theta_i_deg,phi_i_deg,component") and len(rows) == 1 + 5 * len(j["slices"][0]["components"])
    run(["diff", "designed.h5", "produced.h5", "-o", "dp.png", "--theta-i", "20", "--phi-i", "10"])
    png = plt.imread(os.path.join(TMP, "dp.png"))
    assert png.shape[1] == 3 * 256 and png.shape[0] > 256, png.shape
    # A table on another grid is refused, naming both files and the grids.
    other = small_job(os.path.join(TMP, "other.toml"), output="other.h5")
    text = open(other).read().replace("n_theta = 12", "n_theta = 10")
    open(other, "w").write(text)
    run(["run", other], timeout=600)
    p = run(["diff", "designed.h5", "other.h5"], expect=2)
    assert "designed.h5 and other.h5 are on different direction grids" in p.stderr, p.stderr


def program_seconds(result):
    """(pilot seconds, total seconds) of a `run` from its log: the run's "done: ... in X s" plus the
    effects pilots' "in X s" (0 without components = "auto"); mpirun's start-up, about 1-2 s here, is
    not the job's."""
    text = result.stdout + result.stderr
    m = re.search(r"paths in total, ([0-9.]+) s", text)
    assert m, text[-2000:]
    p = re.search(r"pilots \[[0-9,]*\] in ([0-9.e+-]+) s", text)
    pilots = float(p.group(1)) if p else 0.0
    return pilots, float(m.group(1)) + pilots


def test_effects_auto():
    """components = "auto": the effects planner's decisions (with reasons) for scenes with known
    physics, and the auto table against the WM model of the full table (every component, the same
    seeds): per slice sum|f_WM - f_auto| * proj. solid angle, less its expected noise L1 and 3
    standard deviations, stays below the tolerance. Wall times of auto (its pilots included),
    the full table and WM alone are printed (not asserted: speed is measured, not tested). Every
    scene but the noise (no symmetry: 96 tiles of `area` would take minutes; eight listed
    incidences) is the renderer's whole table, every incidence up to 70 deg, as a real job would be:
    the pilots (three incidences) are paid once per job, so the speed-up is what the skipped effects
    save (the paths where nothing scatters twice, `lost`'s masked sums, the transmitted bins), not a
    few listed incidences against the pilots' fixed cost."""
    every = '"all"'
    # The noise has no symmetry (96 tiles of `area` would take minutes): eight listed incidences,
    # so the pilots (three) do not outweigh the job.
    eight = "[[0.0, 0.0], [15.0, 0.0], [20.0, 135.0], [30.0, 45.0], [40.0, 0.0], [50.0, 90.0], [60.0, 0.0], [70.0, 30.0]]"
    scenes = {
        # A coherence length whose lobe (0.01 deg) stays inside the 11 deg bins: no diffraction.
        "flat Al, delta_c = 2 mm": ('kind = "flat"\nsize_um = [10.0, 10.0]', 'name = "Al"',
                                   "coherence_length_um = 2000.0\nincidence_max_deg = 70.0", {"coherent"}, every),
        # Under the sun (50 um) the lobe's 0.39 deg spills across the bins' edges in the bin-averaged
        # table (WS - GS 0.12-0.33 per slice): the noise-free bin-averaged pilots (exact and the
        # facet sum) see it, where beams at the bins' centres saw 0.007.
        "flat Al under the sun": ('kind = "flat"\nsize_um = [10.0, 10.0]', 'name = "Al"',
                                  'light = "sun"\nincidence_max_deg = 70.0', {"coherent", "incoherent"}, every),
        "sine grating, period 2 um = 4 lambda, amplitude 30 nm": (
            'kind = "sine-grating"\nsize_um = [2.0, 0.3]\nperiod_um = 2.0\namplitude_um = 0.03', 'name = "Al"',
            "coherence_length_um = 50.0\nincidence_max_deg = 70.0", {"coherent", "incoherent"}, every),
        "mirror hemispheres under the sun": (
            'kind = "hemispheres"\nsize_um = [10.0, 10.0]\nradius_um = 2.0\nspacing_um = 5.0\nresolution_um = 0.25',
            'name = "mirror"', 'light = "sun"\nincidence_max_deg = 70.0', {"coherent", "incoherent", "multiple"}, every),
        "gentle large-scale noise (rms 0.5 um, correlation 5 um), delta_c = 20 um": (
            'kind = "gaussian"\nsize_um = [20.0, 20.0]\nrms_um = 0.5\ncorrelation_um = 5.0', 'name = "Al"',
            "coherence_length_um = 20.0", {"coherent", "multiple"}, eight),
        "glass sine grating, the renderer needs only the BRDF": (
            'kind = "sine-grating"\nsize_um = [2.0, 0.3]\nperiod_um = 2.0\namplitude_um = 0.03',
            'kind = "dielectric"\nior = 1.5', 'coherence_length_um = 50.0\nneeds = ["brdf"]\nincidence_max_deg = 70.0',
            {"coherent", "incoherent"}, every),
    }
    for k, (name, (geo, mat, scene, expected, incidence)) in enumerate(scenes.items()):
        inc = {"incidence": incidence} if incidence else {}
        auto = effects_job(os.path.join(TMP, f"auto{k}.toml"), geo, mat, scene, **inc)
        # The full table (every component the file can hold) and the paper's WM alone.
        full = effects_job(os.path.join(TMP, f"full{k}.toml"), geo, mat, scene,
                           ["coherent", "incoherent", "multiple", "lost"], **inc)
        wm = effects_job(os.path.join(TMP, f"wm{k}.toml"), geo, mat, scene, ["coherent", "incoherent", "multiple"], **inc)
        plan = run(["plan", auto, "--json", f"plan{k}.json"]).stdout
        decisions = {d["effect"]: d for d in json.load(open(os.path.join(TMP, f"plan{k}.json")))["effects"]["decisions"]}
        r = run(["run", auto, "-o", f"auto{k}.h5"], mpi=2)
        t_pilots, t_auto = program_seconds(r)
        t_full = program_seconds(run(["run", full, "-o", f"full{k}.h5"], mpi=2))[1]
        t_wm = program_seconds(run(["run", wm, "-o", f"wm{k}.h5"], mpi=2))[1]
        with h5py.File(os.path.join(TMP, f"auto{k}.h5"), "r") as a, h5py.File(os.path.join(TMP, f"full{k}.h5"), "r") as b:
            recorded = json.loads(a.attrs["effects_plan"])
            assert set(recorded["components"]) == expected, f"{name}: auto chose {sorted(recorded['components'])}, " \
                f"expected {sorted(expected)}\n{plan}"
            # A skipped `multiple` is verified on every slice: the file holds it (the traced value, or 0
            # where the facet sum computed single scattering and a check bounded it) with the bound.
            # So is a diffraction skip the pilots decided (one the Kirchhoff estimate decided holds for
            # every incidence by construction).
            guarded = {"multiple"} if "multiple" not in expected else set()
            if "incoherent" not in expected and decisions["incoherent"].get("decided_by") == "pilots":
                guarded.add("incoherent")
            got = set(a["bsdf"].keys()) - {"done"}
            assert got == expected | guarded, got
            for c, name_ in (("multiple", "multiple"), ("incoherent", "diffraction")):
                if c not in guarded:
                    continue
                check = a[f"/stats/{name_}_check"][:]
                assert np.all(np.isfinite(check)), check
                assert np.array_equal(a[f"/stats/{name_}_reenabled"][:] != 0, check > recorded["tolerance"]), check
            brdf_only = 'needs = ["brdf"]' in scene
            assert not decisions["btdf"]["on"], decisions["btdf"]
            assert ("only the BRDF" if brdf_only else "conductor transmits nothing") in decisions["btdf"]["reason"]
            if brdf_only:
                # The wave term skipped the transmitted bins: they keep geometric optics, and the
                # comparison is over the BRDF the renderer needs.
                nh = len(a["/grid/projected_solid_angle"]) // 2
                from_below = a["/incidence/theta_deg"][:] > 90
                assert np.all(a["/bsdf/incoherent"][~from_below, :, nh:] == 0)
                assert np.all(a["/bsdf/incoherent"][from_below, :, :nh] == 0)
                if a.attrs.get("wave_estimator") == b.attrs.get("wave_estimator"):
                    assert a["/stats/wave_samples"][:].sum() < b["/stats/wave_samples"][:].sum()
            worst = max(wm_excess_beyond_noise(a, b, brdf_only))
            tol = 0.02
            assert worst < tol, f"{name}: auto differs from WM by {worst} beyond noise (tolerance {tol})"
        reasons = "; ".join(f"{e} {'on' if d['on'] else 'off'}" for e, d in decisions.items())
        print(f"{name} ({'every incidence to 70 deg' if incidence == every else 'eight incidences' if incidence else 'three incidences'}): "
              f"auto = {sorted(expected)}; |auto - WM| beyond noise {max(worst, 0):.4f} < {tol}; "
              f"time auto {t_auto:.2f} s (pilots {t_pilots:.2f} s) vs full {t_full:.2f} s (speed-up {t_full / t_auto:.2f}x), "
              f"vs WM alone {t_wm:.2f} s ({t_wm / t_auto:.2f}x)")
        for e in ("multiple", "incoherent", "btdf"):
            print(f"    {e}: {decisions[e]['reason'][:200]}")


def read_slice_csv(path):
    """Rows of a `slice -o x.csv` file as a dict of numpy columns."""
    with open(path) as f:
        lines = [ln for ln in f if not ln.startswith("#")]
    header = lines[0].strip().split(",")
    rows = [ln.strip().split(",") for ln in lines[1:]]
    cols = {}
    for j, h in enumerate(header):
        values = [r[j] for r in rows]
        try:
            cols[h] = np.array([float(v) for v in values])
        except ValueError:
            cols[h] = values
    return cols


def test_effects_colour():
    """[scene] colour = "rgb" with components = "auto": a renderer fed with colour needs the XYZ of
    each bin, not the spectrum. Rough dispersive BK7 (statistical GGX, one path set per wavelength),
    16 wavelengths: the planner keeps the fewest that reproduce the pilots' XYZ within the
    tolerance; against the 16-wavelength run (same seed) the slices' sum|dXYZ| * proj. solid angle
    per channel, less its noise (standard errors of X, Y, Z from the slice CSV) and 3 standard
    deviations, stays below the tolerance; times are printed (BK7 traces one path set per wavelength,
    so fewer wavelengths are faster; the conductors share their paths). A grey conductor (Al) keeps
    fewer wavelengths than gold, whose reflectance changes across the visible."""
    kept = {}
    listed = "[[0.0, 0.0], [40.0, 0.0], [70.0, 30.0]]"
    # BK7: every incidence (16 tiles by isotropy), enough paths that the run outweighs the pilots.
    for name, material, incidence, paths in (("BK7", 'kind = "dielectric"\nname = "BK7"', '"all"', 100000),
                                             ("Al", 'name = "Al"', listed, 40000), ("Au", 'name = "Au"', listed, 40000)):
        def job(fname, colour, components):
            with open(os.path.join(TMP, fname), "w") as f:
                f.write(f"""[geometry]
kind = "statistical"
ndf = "ggx"
alpha = 0.3
[material]
{material}
[spectrum]
wavelengths_nm = {{ min = 400.0, max = 700.0, count = 16 }}
[directions]
n_theta = 8
n_phi = 16
incidence = {incidence}
[scene]
colour = "{colour}"
tolerance = 0.01
[effects]
components = {json.dumps(components)}
[sampling]
paths_per_slice = {paths}
seed = 11
[output]
path = "{fname}.h5"
""")
            return os.path.join(TMP, fname)
        auto = job(f"colour-{name}.toml", "rgb", ["auto"])
        full = job(f"spectral-{name}.toml", "spectral", ["coherent", "multiple"])
        plan_out = run(["plan", auto, "--json", f"colour-{name}.json"]).stdout
        decisions = {d["effect"]: d for d in json.load(open(os.path.join(TMP, f"colour-{name}.json")))["effects"]["decisions"]}
        wl = decisions["wavelengths"]
        assert "wavelengths_nm" in wl, f"{name}: no reduction\n{plan_out}"
        t_pilots, t_auto = program_seconds(run(["run", auto, "-o", f"colour-{name}.h5"], mpi=2))
        t_full = program_seconds(run(["run", full, "-o", f"spectral-{name}.h5"], mpi=2))[1]
        with h5py.File(os.path.join(TMP, f"colour-{name}.h5"), "r") as a:
            lam = a["/spectrum/wavelength_nm"][:]
            assert np.allclose(lam, wl["wavelengths_nm"]) and len(lam) < 16, lam
            assert set(a["bsdf"].keys()) - {"done"} == {"coherent", "multiple"}
        kept[name] = len(lam)
        worst = -1e9
        for theta, phi in ((0.0, 0.0), (40.0, 0.0), (70.0, 30.0), (140.0, 0.0)) if name == "BK7" else \
                ((0.0, 0.0), (40.0, 0.0), (70.0, 30.0)):
            for side in ([], ["--transmission"]) if name == "BK7" else ([],):
                cols = []
                for fname in (f"colour-{name}.h5", f"spectral-{name}.h5"):
                    out = os.path.join(TMP, f"{fname}-{theta}-{len(side)}.csv")
                    run(["slice", fname, "--theta-i", str(theta), "--phi-i", str(phi), "--model", "GM", "-o", out] + side)
                    cols.append(read_slice_csv(out))
                a, b = cols
                for c in "XYZ":
                    # All exit bins (both hemispheres): the CSV lists them all.
                    op = a["projected_solid_angle_sr"]
                    l1 = np.sum(np.abs(a[c] - b[c]) * op)
                    sd = np.hypot(a[f"stderr_{c}"], b[f"stderr_{c}"]) * op
                    worst = max(worst, l1 - np.sqrt(2 / np.pi) * sd.sum() - 3 * np.sqrt(np.sum(sd ** 2)))
        assert worst < 0.01, f"{name}: colour differs by {worst} beyond noise"
        print(f"{name}: {len(lam)} of 16 wavelengths ({', '.join(f'{x:.0f}' for x in lam)} nm); "
              f"|dXYZ| beyond noise {max(worst, 0):.4f} < 0.01; time {t_auto:.2f} s (pilots {t_pilots:.2f} s) "
              f"vs {t_full:.2f} s (speed-up {t_full / t_auto:.2f}x)\n    {wl['reason'][:160]}")
    assert kept["Al"] < kept["Au"], kept


def test_symmetry():
    """[directions] symmetry: (1) an isotropic Gaussian surface (statistical, Beckmann alpha = 0.4: the
    isotropy is detected from the NDF) computes one incidence azimuth per theta ring and rotates it;
    (2) a square lattice of hemispheres (4-fold rotation and mirror symmetry detected from the mesh)
    computes one azimuth per ring and maps the rest by rotations and the mirror. Against the full computation (symmetry = "none", same seeds) the computed
    slices are the same bytes and the rotated ones agree within their standard errors."""
    cases = [
        ("isotropic Beckmann 0.4, Au", 'kind = "statistical"\nndf = "beckmann"\nalpha = 0.4', 'name = "Au"',
         "symmetry: detected: the surface's NDF is isotropic; 4 tiles for 32 slices", 1),
        ("hemispheres lattice, Al", 'kind = "hemispheres"\nsize_um = [10.0, 10.0]\nradius_um = 2.0\nspacing_um = 5.0',
         'name = "Al"', "symmetry: detected: the patch is invariant under rotation by 90 degrees and the mirror y -> -y; "
         "4 tiles for 32 slices", 1),
    ]
    for k, (name, geometry, material, logline, step) in enumerate(cases):
        def job(fname, symmetry):
            with open(os.path.join(TMP, fname), "w") as f:
                f.write(f"""[geometry]
{geometry}
[material]
{material}
[spectrum]
wavelengths_nm = [450.0, 650.0]
[directions]
n_theta = 4
n_phi = 8
incidence = "all"
symmetry = "{symmetry}"
[effects]
components = ["coherent", "multiple"]
[sampling]
paths_per_slice = 40000
seed = 11
[output]
path = "out.h5"
""")
            return os.path.join(TMP, fname)
        t0 = time.time()
        r = run(["run", job(f"sym{k}.toml", "auto"), "-o", f"sym{k}.h5"], mpi=2)
        t_sym = time.time() - t0
        t0 = time.time()
        run(["run", job(f"full{k}.toml", "none"), "-o", f"full{k}.h5"], mpi=2)
        t_full = time.time() - t0
        assert logline in r.stdout + r.stderr, r.stderr
        plan = run(["plan", job(f"sym{k}.toml", "auto")]).stdout
        assert f"{32 // (8 // step)} computed, the rest rotated" in plan, plan
        with h5py.File(os.path.join(TMP, f"sym{k}.h5"), "r") as a, h5py.File(os.path.join(TMP, f"full{k}.h5"), "r") as b:
            text = lambda v: v.decode() if isinstance(v, bytes) else str(v)  # noqa: E731
            assert text(a.attrs["symmetry"]).startswith("isotropic" if k == 0 else "reduced"), a.attrs["symmetry"]
            inc = a["/incidence/bin"][:]
            fa = a["/bsdf/coherent"][:].astype(float) + a["/bsdf/multiple"][:]
            fb = b["/bsdf/coherent"][:].astype(float) + b["/bsdf/multiple"][:]
            ea = np.hypot(a["/bsdf_stderr/coherent"][:].astype(float), a["/bsdf_stderr/multiple"][:])
            eb = np.hypot(b["/bsdf_stderr/coherent"][:].astype(float), b["/bsdf_stderr/multiple"][:])
            op = a["/grid/projected_solid_angle"][:]
            zs, albedo_z = [], []
            for i, bin_ in enumerate(inc):
                if bin_ % 8 < step:  # a computed (representative) slice
                    assert np.array_equal(a["/bsdf/coherent"][i], b["/bsdf/coherent"][i])
                    assert np.array_equal(a["/bsdf/multiple"][i], b["/bsdf/multiple"][i])
                    continue
                ok = (ea[i] > 0) & (eb[i] > 0)
                zs.extend(((fa[i] - fb[i])[ok] / np.hypot(ea[i], eb[i])[ok]).ravel())
                for l in range(fa.shape[1]):
                    da = np.sum(fa[i, l] * op) - np.sum(fb[i, l] * op)
                    se = np.sqrt(np.sum((ea[i, l] * op) ** 2) + np.sum((eb[i, l] * op) ** 2))
                    albedo_z.append(da / se)
            zs, albedo_z = np.array(zs), np.array(albedo_z)
            beyond = np.mean(np.abs(zs) > 3)
            # 0.27 % of normal z-scores exceed 3; the albedo sums the bins (their errors are negatively
            # correlated within a slice, so its z is conservative).
            assert beyond < 0.01 and 0.7 < np.mean(zs ** 2) < 1.3, (name, beyond, np.mean(zs ** 2))
            assert np.all(np.abs(albedo_z) < 3), (name, albedo_z)
        print(f"{name}: {logline.split('; ')[-1]}; computed slices identical to the full run; rotated slices vs "
              f"full: {zs.size} bins, mean z^2 {np.mean(zs ** 2):.3f}, {100 * beyond:.2f}% beyond 3 SE, albedo |z| <= "
              f"{np.max(np.abs(albedo_z)):.2f}; wall time {t_sym:.1f} s vs {t_full:.1f} s ({t_full / t_sym:.1f}x)")


def test_crash_resume():
    job = many_tiles_job(os.path.join(TMP, "job.toml"), 10, "crash.h5")
    total = 40
    run(["run", job, "-o", "ref.h5"], mpi=2)
    out = os.path.join(TMP, "crash.h5")
    kills = []
    for fraction in (0.1, 0.5, 0.9):
        p = start(["run", job, "-o", "crash.h5", "--resume"])
        if wait_for(p, out, fraction, total):
            # mpirun and every rank at once (Open MPI puts each rank in its own process group, but
            # all stay in mpirun's session).
            subprocess.run(["pkill", "-KILL", "-s", str(p.pid)])
            p.wait()
            wait_session_gone(p.pid)
            kills.append(journal_count(out))
        else:
            p.wait()
    assert len(kills) == 3, f"the job finished before the kills: {kills}"
    assert not os.path.exists(out), "killed runs must not produce the final file"
    r = run(["run", job, "-o", "crash.h5", "--resume"], mpi=2)
    assert "resuming" in r.stdout + r.stderr, r.stdout + r.stderr
    assert datasets(out) == datasets(os.path.join(TMP, "ref.h5")), "resumed datasets differ from an uninterrupted run"
    subprocess.run(["h5dump", "-H", out], check=True, capture_output=True, timeout=60)
    assert not os.path.exists(out + ".journal") and not os.path.exists(out + ".partial")
    print("SIGKILL after", kills, "of", total, "slices; resumed; datasets byte-identical to an uninterrupted run; h5dump reads it")


def test_clean_stop():
    # About 10 s of tiles on 2 ranks, stopped after the first 5 %: mpirun takes up to a few seconds to
    # pass a signal on, less than the 9 s of work still ahead (a 1-s job finished first).
    job = many_tiles_job(os.path.join(TMP, "job.toml"), 10, "stop.h5", paths=200000)
    total = 40
    run(["run", job, "-o", "ref.h5"], mpi=2)
    # SIGTERM to the ranks (what srun and Slurm do), SIGUSR1 to mpirun (it forwards it): the ranks
    # stop at their next batch and exit 3. SIGTERM to mpirun itself makes Open MPI abort the job
    # (exit 1), but the ranks still stop cleanly and leave a resumable file.
    done = {}
    for how, sig, target, code in (("term-ranks", signal.SIGTERM, "children", 3), ("usr1-mpirun", signal.SIGUSR1, "group", 3),
                                   ("term-mpirun", signal.SIGTERM, "group", None)):
        name = f"stop_{how}.h5"
        p = start(["run", job, "-o", name])
        assert wait_for(p, os.path.join(TMP, name), 0.05, total)
        if target == "children":
            subprocess.run(["pkill", "-TERM", "-P", str(p.pid)], check=True)
        else:
            os.killpg(p.pid, sig)
        log, _ = p.communicate(timeout=120)
        wait_session_gone(p.pid)
        if code is not None:
            assert p.returncode == code, f"{how}: exit {p.returncode}\n{log}"
        else:
            assert p.returncode != 0, f"{how}: exit 0"
        partial = os.path.join(TMP, name + ".partial")
        assert os.path.exists(partial) and not os.path.exists(os.path.join(TMP, name)), how
        done[how] = journal_count(os.path.join(TMP, name))
        run(["run", job, "-o", name, "--resume"], mpi=2)
        assert datasets(os.path.join(TMP, name)) == datasets(os.path.join(TMP, "ref.h5")), how
    done_after_term = done
    # --max-hours: a limit of ~1.5 s stops before the end with exit code 3 (on a loaded machine
    # possibly before the first slice); --resume completes.
    out2 = os.path.join(TMP, "maxh.h5")
    r = run(["run", job, "-o", "maxh.h5", "--max-hours", "0.0004"], mpi=2, expect=3)
    done_after_maxh = journal_count(out2)
    assert done_after_maxh < total, done_after_maxh
    run(["run", job, "-o", "maxh.h5", "--resume"], mpi=2)
    assert datasets(out2) == datasets(os.path.join(TMP, "ref.h5"))
    print(f"signals: slices done when stopped {done_after_term} of {total}; --max-hours: exit 3 after "
          f"{done_after_maxh}/{total}; all completed by --resume, byte-identical to an uninterrupted run")


def test_memory():
    def peak_rss(n_theta):
        job = many_tiles_job(os.path.join(TMP, f"mem{n_theta}.toml"), n_theta, f"mem{n_theta}.h5", paths=2000)
        cmd = ["/usr/bin/python3", "-c",
               "import resource, subprocess, sys; subprocess.run(sys.argv[1:], check=True, capture_output=True); "
               "print(resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss)", EXE, "run", job, "-o", f"mem{n_theta}.h5"]
        p = subprocess.run(cmd, capture_output=True, text=True, timeout=600, env=ENV, cwd=TMP, check=True)
        return int(p.stdout.strip())
    small, large = peak_rss(5), peak_rss(50)
    growth = large / small - 1
    print(f"rank 0 peak RSS: {small} KiB for 20 tiles, {large} KiB for 200 tiles: growth {100 * growth:.1f} %")
    assert growth < 0.2, growth


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
    # GM = coherent + multiple
    with h5py.File(os.path.join(TMP, "s.h5"), "r") as f:
        gm = f["bsdf/coherent"][1, 0, :] + f["bsdf/multiple"][1, 0, :]
        # The statistics are of the unrounded values, each stored value within σ/32 of its own
        # (rounded to the noise, docs/output.md).
        sigma = f["bsdf_stderr/coherent"][1, 0, :].astype(float) + f["bsdf_stderr/multiple"][1, 0, :]
        proj = f["grid/projected_solid_angle"][:]
    upper = np.arange(len(proj)) < len(proj) // 2
    rounding = np.sum((sigma / 32 * (1 + 2.0 ** -7) * proj)[upper])
    assert abs(albedo - expected) < rounding + 1e-6 * max(1.0, expected), (albedo, expected, rounding)
    assert np.allclose(np.sort(gm[gm > 0])[-5:], np.sort(rows["f_450nm"])[-5:], rtol=1e-6)
    # The default components are the paper's WM: all four models can be exported.
    for model in ("GS", "WS", "WM", "incoherent"):
        run(["slice", "s.h5", "--theta-i", "20", "--model", model, "-o", f"{model}.csv"])
    r = run(["slice", "s.h5", "--theta-i", "20", "--model", "lost", "-o", "x.csv"], expect=2)
    assert "lost" in r.stderr, r.stderr
    print("slice: CSV albedo", albedo, "matches info", expected)
    # Contact sheet: 4 models (rows) x 5 slices (columns) of 64-pixel cells with labelled margins.
    run(["sheet", "s.h5", "-o", "sheet.png", "--size", "64"])
    png = open(os.path.join(TMP, "sheet.png"), "rb").read()
    assert png[:8] == b"\x89PNG\r\n\x1a\n"
    w, h = struct.unpack(">II", png[16:24])
    assert (w, h) == (24 + 5 * 68, 15 + 4 * 68), (w, h)
    img = plt.imread(os.path.join(TMP, "sheet.png"))
    assert img[15:, :20].max() > 0.9, "row labels missing"   # white glyphs in the left margin
    assert img[:15, 24:].max() > 0.9, "column labels missing"
    run(["sheet", "s.h5", "-o", "sheet2.png", "--models", "GM,WS", "--theta-i", "0,45", "--style", "false"])
    r = run(["sheet", "s.h5", "-o", "x.png", "--models", "XX"], expect=2)
    assert "--models" in r.stderr, r.stderr
    print("sheet:", (w, h))


def gold_ggx_job(name, extra=""):
    """A statistical GGX gold surface (alpha 0.3) at five incidences, declared isotropic so that a
    renderer interpolates between them: a table in a second. Returns the job's path; it writes
    <name>.h5."""
    job = os.path.join(TMP, name + ".toml")
    open(job, "w").write(f"""[geometry]
kind = "statistical"
ndf = "ggx"
alpha = 0.3
[material]
name = "Au"
[spectrum]
wavelengths_nm = [450.0, 550.0, 650.0]
[directions]
n_theta = 18
n_phi = 72
incidence = [[5.0, 0.0], [25.0, 0.0], [45.0, 0.0], [65.0, 0.0], [85.0, 0.0]]
symmetry = "isotropic"
{extra}[sampling]
paths_per_slice = 20000
[output]
path = "{name}.h5"
""")
    return job


def test_render():
    """`render` end to end: a statistical GGX gold table as PNG panels (GS, GM and the closed-form GGX
    reference) and as linear EXR, on the built-in shapes and environments, an OBJ shape and an EXR
    environment; bad options exit 2 naming what is wrong. (The images themselves are checked against
    closed forms by the unit tests in tests/render/.)"""
    job = gold_ggx_job("ggx-render")
    run(["run", job])
    size = 48
    p = run(["render", "ggx-render.h5", "-o", "render.png", "--size", str(size), "--spp", "4",
             "--ggx-reference", "0.3,Au"])
    img = plt.imread(os.path.join(TMP, "render.png"))
    assert img.shape[:2] == (size, 3 * size), f"three panels expected, image {img.shape}"
    for k in range(3):
        panel = img[:, k * size:(k + 1) * size, :3]
        centre = panel[size // 3:2 * size // 3, size // 3:2 * size // 3].mean(axis=(0, 1))
        # Gold: red above blue, in every panel.
        assert centre[0] > centre[2] > 0, f"panel {k}: centre colour {centre}"
    run(["render", "ggx-render.h5", "-o", "render.exr", "--size", "24", "--spp", "2", "--models", "GS"])
    assert open(os.path.join(TMP, "render.exr"), "rb").read(4) == bytes([0x76, 0x2F, 0x31, 0x01]), "not an EXR"
    tetra = os.path.join(TMP, "tetra.obj")
    open(tetra, "w").write("v 0 0 1\nv 1 0 -0.5\nv -0.5 0.87 -0.5\nv -0.5 -0.87 -0.5\n"
                           "f 1 2 3\nf 1 3 4\nf 1 4 2\nf 2 4 3\n")
    # Any float EXR with R, G, B serves as an environment map: a slice of the table is one.
    run(["slice", "ggx-render.h5", "--theta-i", "45", "-o", "env.exr"])
    for shape, env in (("ball", "sky"), (tetra, "studio"), ("sphere", "env.exr")):
        run(["render", "ggx-render.h5", "-o", "r.png", "--size", "24", "--spp", "2", "--models", "GS",
             "--shape", shape, "--environment", env])
    for args, says in ((["--shape", "teapot.stl"], "teapot.stl"), (["--environment", "nowhere.exr"], "nowhere.exr"),
                       (["--tone-curve", "reinhard"], "reinhard"), (["--spp", "0"], "--spp"),
                       (["--ggx-reference", "0.3,BK7"], "BK7"), (["--models", "XX"], "XX")):
        p = run(["render", "ggx-render.h5", "-o", "bad.png", "--size", "24"] + args, expect=2)
        assert says in p.stderr, f"{args}: the error does not name {says}:\n{p.stderr}"
    assert not os.path.exists(os.path.join(TMP, "bad.png"))
    print("render: PNG panels, EXR, shapes, environments and refusals as expected")


def chromium_dom(html, fragment, profile):
    """Opens html#fragment in Debian's headless Chromium with every network request refused, lets its
    scripts run, and returns the DOM as the page left it and the browser's console lines."""
    p = subprocess.run(["chromium", "--headless", "--no-sandbox", "--disable-gpu", "--user-data-dir=" + profile,
                        "--proxy-server=127.0.0.1:9", "--proxy-bypass-list=<-loopback>", "--enable-logging=stderr",
                        "--v=0", "--virtual-time-budget=10000", "--dump-dom", "file://" + html + "#" + fragment],
                       capture_output=True, text=True, timeout=120)
    assert p.returncode == 0, f"chromium exited {p.returncode}:\n{p.stderr[-3000:]}"
    console = [l for l in p.stderr.splitlines() if ":CONSOLE" in l]
    return p.stdout, console


def test_report():
    """`report`: one self-contained HTML file. Opened in headless Chromium with the network cut off:
    no console message and no script error, every part present; the slider's position (set through the
    address, #incidence=K, which sets the slider and fires its own input event) changes the slice pictures, the lobes
    and the label; nothing is fetched from outside the file; bad options exit 2, and a report that
    cannot be written (a folder in its place) exits 2 before any work; the existing report stays as it
    was."""
    job = gold_ggx_job("ggx-report", '[effects]\ncomponents = ["auto"]\n')
    run(["run", job])
    html = os.path.join(TMP, "report.html")
    run(["report", "ggx-report.h5", "-o", html, "--slice-size", "64", "--render-size", "32", "--render-spp", "2"])
    text = open(html, encoding="utf-8").read()
    # Self-contained: no reference leaves the file (the SVG namespace is a name, not an address).
    outside = re.findall(r'(?:src|href)\s*=\s*["\']?(?!data:|#)[a-z]+:|url\(\s*["\']?(?!data:)|@import', text)
    assert not outside, f"references outside the file: {outside[:5]}"
    for part in ("Provenance", "Effects planner", "Slices: energy and errors", "Plane of incidence",
                 "Albedo against", "Material preview", "multiple"):
        assert part in text, f"the report lacks {part}"
    profile = os.path.join(TMP, "chromium-profile")
    doms = {}
    for k in (0, 3):
        dom, console = chromium_dom(html, f"incidence={k}", profile)
        assert not console, f"console messages at #incidence={k}:\n" + "\n".join(console)
        assert 'data-ready="1"' in dom, "the report's script did not finish"
        assert re.search(r'<pre id="errors"></pre>', dom), "script errors: " + dom[dom.find('id="errors"'):][:500]
        assert dom.count("<polyline") >= 2 and dom.count("<circle") >= 5, "lobes or albedo not drawn"
        doms[k] = dom
    def shown(dom, element):
        m = re.search(r'<img id="' + element + r'"[^>]*src="([^"]+)"', dom) or \
            re.search(r'<img[^>]*src="([^"]+)"[^>]*id="' + element + r'"', dom)
        assert m, f"{element} shows no picture"
        return m.group(1)
    for element in ("false-GS", "true-GS", "false-GM"):
        assert shown(doms[0], element) != shown(doms[3], element), f"{element}: the slider does not change it"
    label = lambda dom: re.search(r'id="incidence-label">([^<]*)<', dom).group(1)
    assert "theta_i = 5.00" in label(doms[0]) and "theta_i = 65.00" in label(doms[3]), (label(doms[0]), label(doms[3]))
    lobes = lambda dom: re.search(r'<svg id="lobes".*?</svg>', dom, re.S).group(0)
    assert lobes(doms[0]) != lobes(doms[3]), "the lobes do not follow the slider"
    # Refusals, and a failed write that leaves the existing report whole.
    p = run(["report", "ggx-report.h5", "-o", html, "--slice-size", "8"], expect=2)
    assert "--slice-size" in p.stderr
    before = sha(html)
    p = run(["report", "ggx-report.h5", "-o", TMP, "--render-size", "0"], expect=2)
    assert TMP in p.stderr, p.stderr
    run(["report", "missing.h5", "-o", html], expect=2)
    assert sha(html) == before, "a failed report damaged the existing one"
    print(f"report: {len(text) / 1e6:.2f} MB, opens in headless Chromium without console messages; the slider "
          "changes slices, lobes and label; no reference outside the file")


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
        "ndf.toml": ("[geometry]\nkind = \"statistical\"\nndf = \"cauchy\"\n", "geometry.ndf"),
        "statwave.toml": ("[geometry]\nkind = \"statistical\"\n[effects]\ncomponents = [\"incoherent\"]\n",
                          "effects.components"),
        "fftmesh.toml": ("[geometry]\nkind = \"hemispheres\"\n[scene]\ncoherence_length_um = 50.0\n"
                         "[sampling]\nwave_estimator = \"fft\"\n", "sampling.wave_estimator"),
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


def test_fft_job():
    """A Gaussian heightfield under a coherence window narrower than the patch (speckle), disk grid:
    `auto` resolves to the deterministic fft evaluator; 1 rank and 2 ranks identical; the WS energy
    matches the geometric single-scattering energy at normal incidence; the jobs/paper/noise.toml
    example resolves to fft too."""
    geometry = 'kind = "gaussian"\nsize_um = [10.0, 10.0]\nrms_um = 0.1\ncorrelation_um = 1.0'
    extra = ('[scene]\ncoherence_length_um = 15.0\n[effects]\ncomponents = ["coherent", "incoherent"]\n')
    job = small_job(os.path.join(TMP, "fft.toml"), geometry=geometry, extra=extra)
    text = open(job).read().replace("n_theta = 12\nn_phi = 24", 'grid = "disk"\nwidth = 32\nheight = 32')
    text = text.replace("[[0.0, 0.0], [20.0, 10.0], [45.0, 90.0], [70.0, 200.0], [85.0, 300.0]]",
                        '[[0.0, 0.0], [30.0, 0.0], [60.0, 45.0]]\nincidence_sampling = "exact"')
    open(job, "w").write(text)
    r1 = run(["run", job, "-o", "f1.h5", "--threads", "1"], timeout=600)
    assert "fft estimator" in r1.stderr + r1.stdout, r1.stderr
    run(["run", job, "-o", "f2.h5"], mpi=2, timeout=600)
    assert datasets(os.path.join(TMP, "f1.h5")) == datasets(os.path.join(TMP, "f2.h5")), "1 vs 2 ranks differ"
    info = json.loads(run(["info", "f2.h5", "--json"]).stdout)
    assert info["complete"], info
    for s in info["slices"]:
        refl = s["energy"]["reflected"]
        gs, inc = np.array(refl["coherent"]), np.array(refl["incoherent"])
        assert np.all(np.isfinite(inc)), refl
        print(f"theta_i {s['theta_deg']}: GS {np.round(gs, 4)} WS {np.round(gs + inc, 4)}")
        if s["theta_deg"] == 0.0:
            # A gentle surface (slopes ~0.14) at normal incidence: Kirchhoff's single scattering
            # carries the geometric single-scattering energy to within a few per cent.
            assert np.all(np.abs(inc) < 0.03 * gs), refl
    with h5py.File(os.path.join(TMP, "f2.h5"), "r") as f:
        err = f["bsdf_stderr/incoherent"][()]
        assert np.all(np.isfinite(err)) and np.all(err >= 0)
    r = run(["plan", os.path.join(SRC, "jobs", "paper", "noise.toml")], timeout=600)
    assert "fft" in r.stdout, r.stdout
    print("fft job: 1 and 2 ranks identical; jobs/paper/noise.toml plans with the fft estimator")


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


class LocalSlurm:
    """A one-node Slurm (munge, slurmctld, slurmd) started for a test, with its own slurm.conf."""

    def __init__(self):
        self.dir = os.path.join(TMP, "slurm")
        os.makedirs(os.path.join(self.dir, "state"))
        os.makedirs(os.path.join(self.dir, "spool"))
        host = subprocess.run(["hostname", "-s"], capture_output=True, text=True, check=True).stdout.strip()
        self.conf = os.path.join(self.dir, "slurm.conf")
        d = self.dir
        with open(self.conf, "w") as f:
            f.write(f"""ClusterName=microbsdf-test
SlurmctldHost={host}
MpiDefault=pmix
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
ReturnToService=2
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
StateSaveLocation={d}/state
SlurmdSpoolDir={d}/spool
SlurmctldPidFile={d}/slurmctld.pid
SlurmdPidFile={d}/slurmd.pid
SlurmctldLogFile={d}/slurmctld.log
SlurmdLogFile={d}/slurmd.log
SchedulerType=sched/backfill
SelectType=select/cons_tres
SelectTypeParameters=CR_Core
JobCompType=jobcomp/none
KillWait=5
AuthInfo=cred_expire=10
SchedulerParameters=sched_interval=1,bf_interval=1
AccountingStorageType=accounting_storage/none
NodeName={host} CPUs=2 RealMemory=2000 State=UNKNOWN
PartitionName=debug Nodes={host} Default=YES MaxTime=INFINITE State=UP
""")
        self.env = dict(ENV, SLURM_CONF=self.conf)
        os.makedirs("/run/munge", exist_ok=True)
        shutil.chown("/run/munge", "munge", "munge")
        if subprocess.run(["pgrep", "-x", "munged"], capture_output=True).returncode != 0:
            subprocess.run(["munged", "--force"], check=True, capture_output=True, timeout=30)
        for daemon in ("slurmctld", "slurmd"):
            subprocess.run(["pkill", "-x", daemon], capture_output=True)
        time.sleep(0.5)
        subprocess.run(["slurmctld", "-f", self.conf], check=True, env=self.env, timeout=30)
        subprocess.run(["slurmd", "-f", self.conf], check=True, env=self.env, timeout=30)
        for _ in range(100):
            out = subprocess.run(["sinfo", "-h", "-o", "%T"], capture_output=True, text=True, env=self.env).stdout
            if "idle" in out:
                return
            time.sleep(0.2)
        sys.exit("FAIL: the local Slurm did not come up:\n" + open(os.path.join(d, "slurmctld.log")).read()[-2000:])

    def cmd(self, *args, check=True):
        return subprocess.run(list(args), capture_output=True, text=True, env=self.env, timeout=120, check=check, cwd=TMP)

    def submit(self, script, **env):
        out = subprocess.run(["sbatch", "--chdir", TMP, script], capture_output=True, text=True, check=True,
                             env=dict(self.env, **env), timeout=60, cwd=TMP).stdout
        return out.split()[-1]

    def job(self, jid):
        text = self.cmd("scontrol", "show", "job", jid, check=False).stdout
        return dict(kv.split("=", 1) for kv in text.split() if "=" in kv)

    def wait(self, jid, timeout=300):
        t0 = time.time()
        while time.time() - t0 < timeout:
            info = self.job(jid)
            if info.get("JobState") in ("COMPLETED", "FAILED", "CANCELLED", "TIMEOUT", "NODE_FAIL"):
                return info
            time.sleep(0.5)
        sys.exit(f"FAIL: Slurm job {jid} did not finish")

    def diagnostics(self, jid):
        """What a failed Slurm test needs to be understood: the job, the node and the daemons' logs."""
        text = self.cmd("scontrol", "show", "job", jid, check=False).stdout
        text += self.cmd("scontrol", "show", "node", check=False).stdout
        for name in ("slurmctld.log", "slurmd.log"):
            path = os.path.join(self.dir, name)
            if os.path.exists(path):
                text += f"--- {name} (tail)\n" + "".join(open(path).readlines()[-40:])
        return text

    def stop(self):
        for daemon in ("slurmd", "slurmctld"):
            subprocess.run(["pkill", "-x", daemon], capture_output=True)


def slurm_setup():
    # The sbatch script runs `build/microbsdf` relative to its working directory.
    os.symlink(BUILD, os.path.join(TMP, "build"))
    shutil.copytree(os.path.join(SRC, "jobs"), os.path.join(TMP, "jobs"))
    return LocalSlurm()


def test_slurm_job():
    slurm = slurm_setup()
    try:
        many_tiles_job(os.path.join(TMP, "job.toml"), 3, "out/ref.h5")
        run(["run", "job.toml", "-o", "out/ref.h5"])
        script = os.path.join(SRC, "jobs", "slurm", "microbsdf.sbatch")
        for launcher in ("srun", "mpirun"):
            out = f"out/{launcher}.h5"
            jid = slurm.submit(script, JOB="job.toml", OUT=out, LAUNCHER=launcher)
            info = slurm.wait(jid)
            log = open(os.path.join(TMP, f"microbsdf-{jid}.out")).read()
            assert info["JobState"] == "COMPLETED", f"{launcher}: {info.get('JobState')}\n{log}"
            assert "on 2 ranks" in log, log
            assert datasets(os.path.join(TMP, out)) == datasets(os.path.join(TMP, "out/ref.h5")), launcher
            print(f"sbatch with {launcher}: COMPLETED on 2 ranks, datasets identical to a direct run")
        # A job array over two job files (the parameter-sweep script).
        many_tiles_job(os.path.join(TMP, "a.toml"), 2, "out/a-direct.h5")
        many_tiles_job(os.path.join(TMP, "b.toml"), 3, "out/b-direct.h5")
        with open(os.path.join(TMP, "sweep.txt"), "w") as f:
            f.write("a.toml\nb.toml\n")
        jid = subprocess.run(["sbatch", "--chdir", TMP, "--array=0-1", os.path.join(SRC, "jobs", "slurm", "sweep.sbatch")],
                             capture_output=True, text=True, check=True, timeout=60, cwd=TMP,
                             env=dict(slurm.env, SWEEP="sweep.txt", OUTDIR="out/sweep")).stdout.split()[-1]
        for task in ("0", "1"):
            info = slurm.wait(f"{jid}_{task}")
            assert info["JobState"] == "COMPLETED", info
        for name in ("a", "b"):
            run(["run", f"{name}.toml", "-o", f"out/{name}-direct.h5"])
            assert datasets(os.path.join(TMP, f"out/sweep/{name}.h5")) == datasets(os.path.join(TMP, f"out/{name}-direct.h5"))
        print("job array (sweep.sbatch) over two job files: both COMPLETED with the expected datasets")
        # srun without PMIx: each task would be an MPI job of its own and compute the whole table;
        # Open MPI refuses the direct launch (the isolated singleton start does not hide it).
        p = subprocess.run(["srun", "--mpi=none", "-n", "2", EXE, "run", "job.toml", "-o", "out/no-pmix.h5"],
                           capture_output=True, text=True, timeout=120, env=slurm.env, cwd=TMP)
        assert p.returncode != 0 and 'direct launched using "srun"' in p.stdout + p.stderr, p.stdout + p.stderr
        assert not os.path.exists(os.path.join(TMP, "out/no-pmix.h5"))
        print(f"srun --mpi=none -n 2: refused by Open MPI (srun exit {p.returncode}), no output written")
    finally:
        slurm.stop()


def test_slurm_requeue():
    slurm = slurm_setup()
    try:
        many_tiles_job(os.path.join(TMP, "job.toml"), 10, "out/ref.h5")
        run(["run", "job.toml", "-o", "out/ref.h5"], mpi=2)
        out = os.path.join(TMP, "out/req.h5")
        jid = slurm.submit(os.path.join(SRC, "jobs", "slurm", "microbsdf.sbatch"), JOB="job.toml", OUT="out/req.h5")
        t0 = time.time()
        while journal_count(out) < 8:
            assert time.time() - t0 < 120, "no progress"
            time.sleep(0.1)
        # What Slurm does before the time limit with --signal=B:USR1@300.
        slurm.cmd("scancel", "--signal=USR1", "--batch", jid)
        t0 = time.time()
        while slurm.job(jid).get("Restarts", "0") == "0":
            assert time.time() - t0 < 60, "the job was not requeued"
            time.sleep(0.2)
        # A requeued job waits until the credentials of its first run have expired (slurm.conf
        # AuthInfo=cred_expire, 10 s here, 120 s by default) and Slurm starts it by itself: starting
        # it earlier (scontrol update StartTime=now) races the revocation of those credentials
        # ("Job credential revoked"). Wait for the restarted script's first line rather than for a
        # job state. Every state seen is kept for the failure message.
        log_path = os.path.join(TMP, f"microbsdf-{jid}.out")
        t0 = time.time()
        seen = []
        while "(restart 1)" not in open(log_path).read():
            info = slurm.job(jid)
            state = (info.get("JobState"), info.get("Reason"), info.get("StartTime"))
            if not seen or seen[-1][1:] != state:
                seen.append((round(time.time() - t0, 1),) + state)
            held = "held" in (info.get("Reason") or "").lower()
            if held or time.time() - t0 > 240:
                raise AssertionError("the requeued job did not start:\n" + open(log_path).read()
                                     + "\nstates (s, JobState, Reason, StartTime): " + repr(seen)
                                     + "\n" + slurm.diagnostics(jid))
            time.sleep(0.5)
        print("states while requeued (s, JobState, Reason, StartTime):", seen)
        info = slurm.wait(jid)
        log = open(log_path).read()
        assert info["JobState"] == "COMPLETED", log
        assert "stopped cleanly; requeueing" in log and "resuming:" in log, log
        assert not any(st[1] == "FAILED" for st in seen), f"the clean stop showed as FAILED: {seen}"
        assert datasets(out) == datasets(os.path.join(TMP, "out/ref.h5"))
        print(f"USR1 to the batch script: clean stop, requeued (Restarts={info['Restarts']}), resumed, completed; "
              "datasets identical to an uninterrupted run")
    finally:
        slurm.stop()


run_selected(globals())
