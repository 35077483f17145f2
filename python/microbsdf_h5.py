"""Reading microbsdf output files with h5py (docs/output.md).

The tables /bsdf/<component> and /bsdf_stderr/<component> are (incidence, row, exit bin) arrays in
1/sr, a row per wavelength (/spectrum/wavelength_nm) or, in a file stored in colour, per channel
(X, Y, Z or linear sRGB's R, G, B: `channels`; /colour/weights holds the conversion from the
computed wavelengths, whose per-slice statistics /stats keeps). In the `full` storage profile they are float32 and read as they are. In a profile
with float16 values each slice and wavelength is stored divided by a power of two, kept in
/bsdf_scale/<component> (and /bsdf_stderr_scale/<component>) as an (incidence, wavelength, 1) array;
these functions multiply it back, and where the file stores each same-side pair of incidence bins
once (`pairs = "once"`: the entry (i, o) with o the bin of incidence j < i lives at (j, bin of i))
they fill in the mirrored half, so a script reads every file the same way:

    import h5py, microbsdf_h5
    with h5py.File("out.h5", "r") as f:
        f_ws = microbsdf_h5.slice(f, "coherent", 3) + microbsdf_h5.slice(f, "incoherent", 3)
        err = microbsdf_h5.slice(f, "coherent", 3, error=True)   # where the file keeps per-bin errors

Put this file's folder (python/ in the source tree) on PYTHONPATH, or copy the file beside a script.
It needs only numpy and h5py.
"""

import numpy as np

__all__ = ["table", "slice", "channels", "has_bin_errors", "storage_profile"]


def _paths(component, error):
    group = "bsdf_stderr" if error else "bsdf"
    return f"/{group}/{component}", f"/{group}_scale/{component}"


def channels(f):
    """The tables' rows: ["450nm", ...] per wavelength, or ["X", "Y", "Z"] / ["R", "G", "B"] in colour."""
    if "colour" in f:
        v = f["colour"].attrs["channels"]
        return (v.decode() if isinstance(v, bytes) else str(v)).split(",")
    return [f"{l:g}nm" for l in f["/spectrum/wavelength_nm"][:]]


def has_bin_errors(f, component):
    """Whether the file keeps a per-bin standard error table for `component`."""
    return _paths(component, True)[0] in f


def storage_profile(f):
    """How the file stores its tables (the root attribute storage_profile; "full" before it)."""
    v = f.attrs.get("storage_profile", "full: float32 tables; standard errors per bin")
    return v.decode() if isinstance(v, bytes) else str(v)


def _read(f, component, error, index):
    path, scale_path = _paths(component, error)
    if path not in f:
        if error and f"/bsdf/{component}" in f:
            raise KeyError(f"{f.filename} stores the standard errors of '{component}' per slice only "
                           f"(/stats; storage profile: {storage_profile(f)})")
        raise KeyError(f"{f.filename} has no component '{component}'")
    values = f[path][index].astype(np.float64)
    if scale_path in f:
        values *= f[scale_path][index]  # (…, rows, 1) broadcasts over the exit bins
    return values


def _pairs(f, component, error):
    """Whether the table stores each same-side pair of incidence bins once, and the incidences' bins
    and sides."""
    path = _paths(component, error)[0]
    if "pairs" not in f[path].attrs:
        return None
    bins = f["/incidence/bin"][:].astype(int)
    upper = f["/grid/theta_deg"][:][bins] < 90
    return bins, upper


def table(f, component, error=False):
    """The whole table of `component` (its standard errors with error=True): (incidence, row, bin), 1/sr.

    Where the file stores each same-side pair of incidence bins once (storage profile), entry (i, o)
    with o the bin of incidence j < i lives at (j, bin of i): filled in here."""
    t = _read(f, component, error, np.s_[...])
    pairs = _pairs(f, component, error)
    if pairs is not None:
        bins, upper = pairs
        i, j = np.tril_indices(len(bins), -1)  # j < i
        same = upper[i] == upper[j]
        i, j = i[same], j[same]
        t[i, :, bins[j]] = t[j, :, bins[i]]
    return t


def slice(f, component, incidence, error=False):  # noqa: A001 (the file's own word for it)
    """One incidence slice of `component` (its standard errors with error=True): (row, bin), 1/sr."""
    i = int(incidence)
    row = _read(f, component, error, np.s_[i])
    pairs = _pairs(f, component, error)
    if pairs is not None:
        bins, upper = pairs
        path, scale_path = _paths(component, error)
        column = f[path][:, :, bins[i]].astype(np.float64)  # (incidence, row): f(j -> bin of i)
        if scale_path in f:
            column *= f[scale_path][:, :, 0]
        j = np.nonzero((np.arange(len(bins)) < i) & (upper == upper[i]))[0]
        row[:, bins[j]] = column[j, :].T
    return row
