#!/usr/bin/python3
"""Lobes and albedos from a microbsdf output file (paper Fig. 8 style), with Debian's matplotlib and h5py.

    scripts/plot_lobes.py out/quickstart.h5 -o lobes.png [--theta-i 30 60] [--models GS GM WS WM] [--lambda-nm 550]

Left: f in the plane of incidence (exit directions with φo = φi on the right, φo = φi + 180° on the
left, so the specular direction is at +θi) for each model the file can form, one line style per
model and one colour per incidence angle, log scale. Right: albedo (Σ f·Ω⊥ over the upper and lower
hemispheres) against θi per component. Models are sums of components (GS = coherent, GM = coherent
+ multiple, WS = coherent + incoherent, WM = all three); a model whose components are not in the
file is skipped. Bins are those of the file's theta-phi grid whose φ range contains the plane.
"""
import argparse
import sys

import h5py
import matplotlib
import numpy as np

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

MODELS = {"GS": ["coherent"], "GM": ["coherent", "multiple"], "WS": ["coherent", "incoherent"],
          "WM": ["coherent", "incoherent", "multiple"]}


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("file")
    ap.add_argument("-o", "--output", required=True)
    ap.add_argument("--theta-i", type=float, nargs="*", help="incidence angles (nearest computed slices; default all)")
    ap.add_argument("--models", nargs="*", default=["GS", "GM", "WS", "WM"])
    ap.add_argument("--lambda-nm", type=float, default=None, help="wavelength (nearest; default: mean over λ)")
    a = ap.parse_args()

    # swmr=True: a partial file (a run still writing it, or killed) opens like a finished one.
    with h5py.File(a.file, "r", swmr=True) as f:
        comps = [c for c in f["bsdf"].keys() if c != "done"]
        done = f["bsdf/done"][()].astype(bool)
        if not done.all():
            print(f"warning: incomplete: {done.sum()} of {len(done)} slices; only computed slices are plotted",
                  file=sys.stderr)
        if not done.any():
            sys.exit(f"{a.file}: no slice is computed yet")
        th_i = f["incidence/theta_deg"][()]
        ph_i = f["incidence/phi_deg"][()]
        gth = f["grid/theta_deg"][()]
        gph = f["grid/phi_deg"][()]
        omp = f["grid/projected_solid_angle"][()]
        wl = f["spectrum/wavelength_nm"][()]
        lam = slice(None) if a.lambda_nm is None else int(np.argmin(np.abs(wl - a.lambda_nm)))
        kind = f.attrs.get("grid_kind", "theta-phi")
        if (kind.decode() if isinstance(kind, bytes) else kind) != "theta-phi":
            sys.exit("plot_lobes.py needs a theta-phi grid (the plane of incidence is a column of bins)")
        idx = [i for i in range(len(th_i)) if done[i]]
        if a.theta_i:
            idx = sorted({min(idx, key=lambda i: abs(th_i[i] - t)) for t in a.theta_i})
        data = {c: f["bsdf/" + c] for c in comps}
        # The models this file can form from its components; the others are left out and said so.
        shown = [m for m in a.models if all(c in data for c in MODELS[m])]
        missing = [m for m in a.models if m not in shown]
        if missing:
            print(f"note: {a.file} holds {sorted(comps)}: no {', '.join(missing)}", file=sys.stderr)
        if not shown:
            sys.exit(f"{a.file}: none of the models {a.models} can be formed from its components {sorted(comps)}")

        fig, ax = plt.subplots(1, 2, figsize=(12, 4.5))
        styles = {"GS": ":", "GM": "-", "WS": "--", "WM": "-."}
        upper = gth <= 90
        dphi = np.median(np.diff(np.unique(gph)))
        for n, i in enumerate(idx):
            color = f"C{n % 10}"
            # Bins whose φ centre is within half a bin of the plane, on both sides.
            def column(phi):
                d = np.abs((gph - phi + 180) % 360 - 180)
                return np.where(upper & (d <= dphi / 2 + 1e-9))[0]
            fwd, back = column(ph_i[i] + 180), column(ph_i[i])
            for m in shown:
                tab = sum(np.asarray(data[c][i, lam, :]) for c in MODELS[m])
                if tab.ndim == 2:
                    tab = tab.mean(axis=0)
                x = np.concatenate([-gth[back], gth[fwd]])
                y = np.concatenate([tab[back], tab[fwd]])
                o = np.argsort(x)
                ax[0].semilogy(x[o], np.maximum(y[o], 1e-6), styles[m], color=color,
                               label=f"{m}, θi = {th_i[i]:.0f}°")
        ax[0].set_xlabel("θo in the plane of incidence (°; + : forward, − : back)")
        ax[0].set_ylabel("f (1/sr)" + ("" if a.lambda_nm is None else f" at {wl[lam]:.0f} nm"))
        ax[0].legend(fontsize=7, ncol=2)
        ax[0].set_title("lobes")

        order = np.argsort(th_i[idx])
        for n, c in enumerate(comps):
            alb = []
            for i in np.array(idx)[order]:
                e = f["stats/energy_reflected/" + c][i, :, 0] + f["stats/energy_transmitted/" + c][i, :, 0]
                alb.append(float(np.mean(e)) if a.lambda_nm is None else float(e[lam]))
            ax[1].plot(th_i[idx][order], alb, "o-", label=c)
        ax[1].axhline(0, color="grey", lw=0.5)
        ax[1].set_xlabel("θi (°)")
        ax[1].set_ylabel("albedo Σ f·Ω⊥ (reflected + transmitted)")
        ax[1].set_title("albedo per component")
        ax[1].legend(fontsize=8)
        title = f.attrs["job_file"] if "job_file" in f.attrs else a.file
        fig.suptitle(title.decode() if isinstance(title, bytes) else str(title), fontsize=9)
        fig.tight_layout()
        fig.savefig(a.output, dpi=100)
    print(f"wrote {a.output} ({len(idx)} slices, models {shown})")


if __name__ == "__main__":
    main()
