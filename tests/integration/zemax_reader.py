"""An independent reader of Zemax OpticStudio's tabular BSDF files (the BSDF Data Interchange format,
Rykowski 2008), written from the format's description, not from microbsdf's writer: the header
keywords in their order, each enumeration's count, one "TIS" line and ScatterAzimuth rows of
ScatterRadial values per sample rotation and angle of incidence, DataBegin ... DataEnd — once for
Monochrome, and as TristimulusX, TristimulusY and TristimulusZ sets for XYZ. It also integrates
f cos(theta_o) over the tabulated scatter directions (radial r from the specular direction — reflected
for a BRDF, of direct transmission for a BTDF — azimuth a from the direction towards the normal of
that side: cos theta_o = cos r cos theta_s + sin r cos a sin theta_s, theta_s the AngleOfIncidence)
and interpolates f at a scatter direction the way a tabular lookup does (bilinear in radial and
azimuth). `channel` selects a tristimulus set (0, 1, 2 = X, Y, Z)."""
import numpy as np

HEADER = ["Source", "Symmetry", "SpectralContent", "ScatterType"]
ENUMS = ["SampleRotation", "AngleOfIncidence", "ScatterAzimuth", "ScatterRadial"]


class ZemaxBsdf:
    def __init__(self, path):
        with open(path) as f:
            lines = [ln.strip() for ln in f if not ln.lstrip().startswith("#")]
        it = iter([ln for ln in lines])
        self.keys = {}
        for key in HEADER:
            words = next(it).split()
            assert words[0] == key, f"{path}: expected {key}, found {words[0]}"
            self.keys[key] = words[1]
        assert self.keys["Source"] == "Measured", self.keys
        # The format description spells "ASymmetrical4D"; some writers spell "Asymmetrical4D".
        assert self.keys["Symmetry"] in ("PlaneSymmetrical", "Asymmetrical", "ASymmetrical4D", "Asymmetrical4D"), self.keys
        assert self.keys["SpectralContent"] in ("Monochrome", "XYZ"), self.keys
        assert self.keys["ScatterType"] in ("BRDF", "BTDF"), self.keys
        self.enums = {}
        for key in ENUMS:
            words = next(it).split()
            assert words[0] == key and len(words) == 2, f"{path}: expected '{key} <count>', found {words}"
            n = int(words[1])
            values = np.array([float(x) for x in next(it).split()])
            assert len(values) == n, f"{path}: {key} announces {n} values, lists {len(values)}"
            assert np.all(np.diff(values) > 0), f"{path}: {key} not ascending"
            self.enums[key] = values
        if self.keys["Symmetry"].lower() != "asymmetrical4d":
            assert len(self.enums["SampleRotation"]) == 1, "several rotations need Asymmetrical4D"
        az, rad = self.enums["ScatterAzimuth"], self.enums["ScatterRadial"]
        assert rad[0] == 0 and rad[-1] <= 180, rad
        assert az[0] == 0 and az[-1] < 360, az
        line = next(it)
        while line == "":
            line = next(it)
        names = ["Monochrome"] if self.keys["SpectralContent"] == "Monochrome" else \
            ["TristimulusX", "TristimulusY", "TristimulusZ"]
        self.tis_sets, self.data_sets = [], []
        for n, name in enumerate(names):
            if n > 0:
                line = next(it)
            assert line == name, f"expected {name}, found {line}"
            assert next(it) == "DataBegin"
            tis, data = [], []
            for _ in self.enums["SampleRotation"]:
                tis_row, data_row = [], []
                for _ in self.enums["AngleOfIncidence"]:
                    words = next(it).split()
                    assert words[0] == "TIS" and len(words) == 2, words
                    tis_row.append(float(words[1]))
                    block = np.array([[float(x) for x in next(it).split()] for _ in az])
                    assert block.shape == (len(az), len(rad)), block.shape
                    assert np.all(np.isfinite(block)) and np.all(block >= 0), "f must be finite and >= 0"
                    # Radial 0 is one direction whatever the azimuth.
                    assert np.allclose(block[:, 0], block[0, 0], rtol=1e-5), block[:, 0]
                    data_row.append(block)
                tis.append(tis_row)
                data.append(data_row)
            assert next(it) == "DataEnd"
            self.tis_sets.append(np.array(tis))
            self.data_sets.append(data)
        assert all(ln == "" for ln in it), "text after the last DataEnd"
        self.tis, self.data = self.tis_sets[0], self.data_sets[0]

    def integral(self, rot, k, channel=0):
        """∫ f cos(theta_o) dΩ over the tabulated directions on the file's side (trapezoid in r, the
        azimuths as equal sectors of the full turn)."""
        theta = np.radians(self.enums["AngleOfIncidence"][k])
        r = np.radians(self.enums["ScatterRadial"])
        a = np.radians(self.enums["ScatterAzimuth"])
        f = self.data_sets[channel][rot][k]
        cos_o = np.cos(r)[None, :] * np.cos(theta) + np.sin(r)[None, :] * np.cos(a)[:, None] * np.sin(theta)
        g = f * np.clip(cos_o, 0, None) * np.sin(r)[None, :]
        per_azimuth = np.trapz(g, r, axis=1)
        return float(np.sum(per_azimuth) * (2 * np.pi / len(a)))

    def lookup(self, rot, k, r_deg, a_deg, channel=0):
        """f at radial r and azimuth a, bilinear in the table (azimuth periodic)."""
        rad, az = self.enums["ScatterRadial"], self.enums["ScatterAzimuth"]
        f = self.data_sets[channel][rot][k]
        j = min(np.searchsorted(rad, r_deg, side="right") - 1, len(rad) - 2)
        t = (r_deg - rad[j]) / (rad[j + 1] - rad[j])
        step = 360.0 / len(az)
        i0 = int(np.floor(a_deg / step)) % len(az)
        i1 = (i0 + 1) % len(az)
        s = (a_deg - az[i0]) / step if a_deg >= az[i0] else (a_deg + 360 - az[i0]) / step
        row0 = (1 - t) * f[i0, j] + t * f[i0, j + 1]
        row1 = (1 - t) * f[i1, j] + t * f[i1, j + 1]
        return (1 - s) * row0 + s * row1
