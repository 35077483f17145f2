#!/usr/bin/python3
"""Measured topography input: X3P, SDF and GSF files from independent writers (python/topography_files.py,
written from the formats' descriptions) load with exact heights, malformed ones end in a clear error,
and a heightfield from X3P gives byte-identical tables to the same heights from EXR.

Usage: topography_test.py BUILD_DIR SOURCE_DIR TEST_NAME (see harness.py)."""
import os
import sys
import zipfile

import h5py
import numpy as np

from harness import *  # noqa: F401,F403 (BUILD, SRC, EXE, TMP, run, small_job, datasets, ...)

sys.path.insert(0, os.path.join(SRC, "python"))
from topography_files import write_exr, write_gsf, write_sdf_binary, write_sdf_text, write_x3p  # noqa: E402


def heightfield_job(name, file, extra=""):
    """A job on the heightfield `file` (levelling off unless `extra` says otherwise)."""
    geometry = f'kind = "heightfield"\nfile = "{file}"\n' + (extra if "level" in extra else 'level = "none"\n' + extra)
    return small_job(os.path.join(TMP, name), geometry=geometry)


def loaded_heights(file, extra=""):
    """The heights microbsdf meshes from `file`, through `check --heights` (double, µm), and check's text."""
    job = heightfield_job("h.toml", file, extra)
    p = run(["check", job, "--heights", "heights.h5"])
    with h5py.File(os.path.join(TMP, "heights.h5"), "r") as f:
        d = f["heights_um"]
        return d[...], float(d.attrs["dx_um"]), float(d.attrs["dy_um"]), p.stdout


def expect_exact(name, file, z_um, dx_um, dy_um, valid=None, extra=""):
    h, dx, dy, text = loaded_heights(file, extra)
    assert h.shape == z_um.shape, (name, h.shape, z_um.shape)
    assert (dx, dy) == (dx_um, dy_um), (name, dx, dy, dx_um, dy_um)
    mask = np.ones(z_um.shape, bool) if valid is None else valid
    bad = np.flatnonzero(h[mask] != z_um[mask])
    assert bad.size == 0, f"{name}: {bad.size} heights differ, first {h[mask][bad[:3]]} vs {z_um[mask][bad[:3]]}"
    if valid is not None:
        missing = int((~valid).sum())
        assert f"{missing} unmeasured points" in text, (name, text)
        assert np.all(np.isfinite(h)), name
        # The Laplace fill stays within the range of what was measured (a discrete maximum principle).
        assert h[~valid].min() >= z_um[valid].min() - 1e-12 and h[~valid].max() <= z_um[valid].max() + 1e-12, name
    print(f"{name}: {h.shape[1]} x {h.shape[0]} heights exact" + (f", {int((~valid).sum())} filled" if valid is not None
                                                                    else ""))


def test_readers_exact():
    rng = np.random.default_rng(3)
    ny, nx = 9, 12
    dx_m, dy_m = 0.25e-6, 0.5e-6
    dx_um, dy_um = dx_m * 1e6, dy_m * 1e6
    os.chdir(TMP)
    # X3P: each data type, z = offset + increment * value (metres).
    for ztype, raw, zinc, zoff in (
            ("I", rng.integers(-32768, 32767, (ny, nx)), 1e-9, 2.5e-8),
            ("L", rng.integers(-2**31, 2**31 - 1, (ny, nx)), 1e-15, -1e-7),
            ("F", rng.normal(0, 5e-8, (ny, nx)).astype(np.float32), 1.0, 0.0),
            ("D", rng.normal(0, 5e-8, (ny, nx)), 1.0, 3e-9)):
        write_x3p(f"{ztype}.x3p", raw, dx_m, dy_m, ztype=ztype, zinc=zinc, zoff=zoff)
        z_um = (zoff + zinc * raw.astype(np.float64)) * 1e6
        expect_exact(f"X3P {ztype}", f"{ztype}.x3p", z_um, dx_um, dy_um)
    # The valid-points mask (binary) and empty <Datum> (inline) mark points not measured.
    raw = rng.normal(0, 5e-8, (ny, nx))
    valid = rng.random((ny, nx)) > 0.15
    valid[0, 0] = True
    write_x3p("mask.x3p", raw, dx_m, dy_m, ztype="D", valid=valid)
    expect_exact("X3P D with a valid-points mask", "mask.x3p", raw * 1e6, dx_um, dy_um, valid=valid)
    write_x3p("inline.x3p", raw, dx_m, dy_m, ztype="D", valid=valid, inline=True)
    expect_exact("X3P inline DataList with empty Datum", "inline.x3p", raw * 1e6, dx_um, dy_um, valid=valid)
    # NaN in float data is a point not measured too.
    nan = raw.copy()
    nan[~valid] = np.nan
    write_x3p("nan.x3p", nan, dx_m, dy_m, ztype="F")
    expect_exact("X3P F with NaN", "nan.x3p", nan.astype(np.float32).astype(np.float64) * 1e6, dx_um, dy_um,
                 valid=valid)
    # SDF, text and binary: z = value * Zscale metres.
    ints = rng.integers(-30000, 30000, (ny, nx))
    write_sdf_text("t7.sdf", raw, dx_m, dy_m, 1.0, datatype=7)
    expect_exact("SDF text double", "t7.sdf", raw * 1e6, dx_um, dy_um)
    write_sdf_text("t5.sdf", ints, dx_m, dy_m, 1e-10, datatype=5)
    expect_exact("SDF text int16", "t5.sdf", ints * 1e-10 * 1e6, dx_um, dy_um)
    for dt, vals, zs in ((3, raw.astype(np.float32), 1.0), (6, ints, 1e-10), (7, raw, 1.0), (1, ints + 30000, 1e-10)):
        write_sdf_binary(f"b{dt}.sdf", vals, dx_m, dy_m, zs, datatype=dt)
        expect_exact(f"SDF binary DataType {dt}", f"b{dt}.sdf", vals.astype(np.float64) * zs * 1e6, dx_um, dy_um)
    # GSF: float32 values in ZUnits, the field's size in XYUnits.
    z32 = rng.normal(0, 40, (ny, nx)).astype(np.float32)
    write_gsf("nm.gsf", z32, 3.0, 4.5, xy_units="um", z_units="nm")
    expect_exact("GSF (nm heights, µm field)", "nm.gsf", z32.astype(np.float64) * 1e-3, 3.0 / nx, 4.5 / ny)
    gnan = z32 * np.float32(1e-9)  # nanometre heights, stored in metres
    gnan[~valid] = np.nan
    write_gsf("nan.gsf", gnan, 3e-6, 4.5e-6)
    expect_exact("GSF with NaN", "nan.gsf", gnan.astype(np.float64) * 1e6, 3e-6 * 1e6 / nx, 4.5e-6 * 1e6 / ny,
                 valid=valid)


def test_x3p_from_other_software():
    """Layouts other X3P writers produce, which other readers accept: each is read with the heights
    the writer stored and a warning naming the file and what was unusual. A point data checksum
    that does not match stays an error (test_readers_malformed)."""
    rng = np.random.default_rng(5)
    ny, nx = 7, 10
    raw = rng.normal(0, 4e-8, (ny, nx))
    os.chdir(TMP)
    for layout, ztype, warning in ((dict(layout="folder"), "D", "is in the folder 'folder/'"),
                                   (dict(layout="folder", valid=rng.random((ny, nx)) > 0.2), "D",
                                    "is in the folder 'folder-mask/'"),
                                   (dict(layout="empty-offset", zoff=3e-7), "L", "has an empty <Offset>"),
                                   (dict(corrupt="main-md5"), "D", "MD5 checksum of main.xml does not match"),
                                   (dict(layout="root-iso5436"), "D", "<p:ISO5436>, not <ISO5436_2>")):
        name = {"folder": "folder", "empty-offset": "offset", "root-iso5436": "root"}.get(layout.get("layout"),
                                                                                        "main-md5")
        if "valid" in layout:
            name = "folder-mask"
        stored = np.round(raw / 1e-10) if ztype == "L" else raw
        zinc = 1e-10 if ztype == "L" else 1.0
        write_x3p(f"{name}.x3p", stored, 0.5e-6, 0.5e-6, ztype=ztype, zinc=zinc, **layout)
        h, dx, dy, text = loaded_heights(f"{name}.x3p")
        p = run(["check", heightfield_job("w.toml", f"{name}.x3p")])
        assert warning in p.stdout + p.stderr and f"{name}.x3p" in p.stdout + p.stderr, (name, p.stdout, p.stderr)
        # An independent parse: the values the writer stored, times the increment, in micrometres.
        want = stored * zinc * 1e6
        valid = layout.get("valid")
        mask = np.ones(want.shape, bool) if valid is None else valid
        assert (dx, dy) == (0.5, 0.5), (name, dx, dy)
        assert np.array_equal(h[mask], want[mask]), (name, np.abs(h[mask] - want[mask]).max())
        print(f"{name}.x3p: heights exact; warned: {warning}")


def expect_error(file, *phrases):
    job = heightfield_job("bad.toml", file)
    p = run(["check", job], expect=2)
    for phrase in (file,) + phrases:
        assert phrase in p.stderr, f"{file}: '{phrase}' not in: {p.stderr}"
    print(f"{file}: {p.stderr.strip().splitlines()[-1]}")


def test_readers_malformed():
    rng = np.random.default_rng(4)
    z = rng.normal(0, 5e-8, (6, 8))
    os.chdir(TMP)
    for corrupt, phrase in (("xml", "main.xml line 11"), ("missing-bin", "no member 'bindata/data.bin'"),
                            ("short-bin", "need 384"),
                            ("data-md5", "MD5 checksum of 'bindata/data.bin'"), ("feature", "FeatureType PRF"),
                            ("axis", "AxisType A"), ("rotation", "carry a rotation")):
        write_x3p(f"{corrupt}.x3p", z, 1e-6, 1e-6, corrupt=corrupt)
        expect_error(f"{corrupt}.x3p", phrase)
    with open("notzip.x3p", "wb") as f:
        f.write(b"PK\x03\x04 this is not a zip archive")
    expect_error("notzip.x3p", "not a readable X3P")
    # main.xml in two folders of one archive: which is the surface is not known.
    write_x3p("one.x3p", z, 1e-6, 1e-6, layout="folder")
    with zipfile.ZipFile("one.x3p") as src, zipfile.ZipFile("two.x3p", "w") as dst:
        for info in src.infolist():
            for top in ("a/", "b/"):
                dst.writestr(top + info.filename, src.read(info))
    expect_error("two.x3p", "2 in folders")
    write_sdf_text("short.sdf", z, 1e-6, 1e-6, 1.0, truncate=True)
    expect_error("short.sdf", "43 height values")
    write_sdf_binary("shortb.sdf", z, 1e-6, 1e-6, 1.0)
    with open("shortb.sdf", "r+b") as f:
        f.truncate(81 + 8 * 47)
    expect_error("shortb.sdf", "need 384 bytes")
    write_sdf_text("badkey.sdf", z, 1e-6, 1e-6, 1.0)
    text = open("badkey.sdf").read().replace("Xscale      = 1e-06", "Xscale      = 1e-06x")
    open("badkey.sdf", "w").write(text)
    expect_error("badkey.sdf", "line 7", "Xscale")
    write_gsf("nounits.gsf", z.astype(np.float32), 1e-6, 1e-6, drop_units=True)
    expect_error("nounits.gsf", "no XYUnits")
    write_gsf("cut.gsf", z.astype(np.float32), 1e-6, 1e-6)
    with open("cut.gsf", "r+b") as f:
        f.truncate(os.path.getsize("cut.gsf") - 4)
    expect_error("cut.gsf", "need 192 bytes")
    # A pitch given twice (job and file) is refused, naming the key.
    write_x3p("ok.x3p", z, 1e-6, 1e-6)
    job = heightfield_job("twice.toml", "ok.x3p", "texel_um = 0.5\n")
    p = run(["check", job], expect=2)
    assert "texel_um" in p.stderr and "ok.x3p" in p.stderr, p.stderr


def test_x3p_equals_exr():
    """The same float32 heights (metres) as X3P (type F) and as EXR (height_scale = 1e6): the same
    mesh, so byte-identical tables."""
    rng = np.random.default_rng(5)
    ny, nx = 32, 32
    texel_m = 0.3125e-6  # 0.3125 µm: texel_um = texel_m * 1e6 exactly, as the X3P reader computes it
    assert texel_m * 1e6 == 0.3125
    z = (rng.normal(0, 0.1e-6, (ny, nx))).astype(np.float32)
    os.chdir(TMP)
    write_x3p("s.x3p", z, texel_m, texel_m, ztype="F")
    write_exr("s.exr", z)
    jx = heightfield_job("x.toml", "s.x3p")
    je = heightfield_job("e.toml", "s.exr", "texel_um = 0.3125\nheight_scale = 1e6\n")
    for job, out in ((jx, "x.h5"), (je, "e.h5")):
        text = open(job).read().replace('path = "out.h5"', f'path = "{out}"')
        open(job, "w").write(text)
        run(["run", job], mpi=2, timeout=600)
    a, b = datasets(os.path.join(TMP, "x.h5")), datasets(os.path.join(TMP, "e.h5"))
    assert a == b, "X3P and EXR tables differ"
    with h5py.File(os.path.join(TMP, "x.h5"), "r") as fx, h5py.File(os.path.join(TMP, "e.h5"), "r") as fe:
        assert fx.attrs["geometry_hash"] == fe.attrs["geometry_hash"]
    print("X3P (F, metres) and EXR (float32 metres x 1e6): byte-identical datasets", sorted(a))


run_selected(globals())
