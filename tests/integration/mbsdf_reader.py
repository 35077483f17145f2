"""An independent reader of NVIDIA's measured BSDF files (`.mbsdf`), written from the format's
description (the MDL specification's appendix on measured BSDF data, and the MDL SDK's loader and
runtime), for the export tests.

It parses the header, the metadata lines and each data block with its byte count as the SDK's loader
does, and evaluates f the way the SDK's runtime does: the azimuth difference folded into [0, pi], the
coordinates (dphi / pi, theta_o * 2 / pi, theta_i * 2 / pi) looked up with linear filtering on
cell-centred nodes (texel k at (k + 1/2) / n, held at the edges), on the data made symmetric,
(f(ti, to) + f(to, ti)) / 2 -- or, with symmetrise=False, on the data as stored."""
import math
import struct

import numpy as np

MAGIC = b"NVIDIA ARC MBSDF V1\n"
BLOCKS = {b"MBSDF_DATA=\n": "reflection", b"MBSDF_DATA_REFLECTION=\n": "reflection",
          b"MBSDF_DATA_TRANSMISSION=\n": "transmission"}


def _line(raw, pos):
    end = raw.index(b"\n", pos) + 1
    return raw[pos:end], end


class Mbsdf:
    def __init__(self, path):
        with open(path, "rb") as f:
            raw = f.read()
        assert raw.startswith(MAGIC), "bad magic"
        pos, self.metadata, self.parts = len(MAGIC), {}, {}
        line, pos = _line(raw, pos)
        while line not in BLOCKS:
            key, _, value = line.decode().rstrip("\n").partition("=")
            assert key and value.startswith('"') and value.endswith('"'), f"metadata line {line!r}"
            self.metadata[key] = value[1:-1]
            line, pos = _line(raw, pos)
        while True:
            part = BLOCKS[line]
            assert part not in self.parts, f"two {part} blocks"
            kind, n_theta, n_phi = struct.unpack_from("<III", raw, pos)
            pos += 12
            assert kind in (0, 1) and n_theta > 0 and n_phi > 0, (kind, n_theta, n_phi)
            channels = 3 if kind == 1 else 1
            count = n_theta * n_theta * n_phi * channels
            assert pos + 4 * count <= len(raw), f"{part}: {len(raw) - pos} bytes for {4 * count}"
            data = np.frombuffer(raw, "<f4", count, pos).reshape(n_theta, n_theta, n_phi, channels)
            pos += 4 * count
            assert np.all(np.isfinite(data)) and np.all(data >= 0), f"{part}: values negative or not finite"
            self.parts[part] = data.astype(np.float64)
            if pos == len(raw):
                break
            line, pos = _line(raw, pos)
            assert line in BLOCKS and BLOCKS[line] == "transmission" and part == "reflection", f"then {line!r}"

    def table(self, part, symmetrise=True):
        d = self.parts[part]
        return 0.5 * (d + d.transpose(1, 0, 2, 3)) if symmetrise else d

    def eval(self, part, theta_i, phi_i, theta_o, phi_o, symmetrise=True):
        """f per channel; theta_o from the normal of the side of `part` (radians)."""
        d = self.table(part, symmetrise)
        n_theta, n_phi = d.shape[0], d.shape[2]
        u = phi_o - phi_i
        if u < 0:
            u += 2 * math.pi
        if u > math.pi:
            u = 2 * math.pi - u

        def axis(x, n):  # linear filtering of normalised coordinate x on n cell-centred texels, clamped
            t = x * n - 0.5
            i0 = math.floor(t)
            w = t - i0
            return min(max(i0, 0), n - 1), min(max(i0 + 1, 0), n - 1), w

        a0, a1, wa = axis(theta_i * 2 / math.pi, n_theta)
        b0, b1, wb = axis(theta_o * 2 / math.pi, n_theta)
        c0, c1, wc = axis(u / math.pi, n_phi)
        out = 0.0
        for ia, fa in ((a0, 1 - wa), (a1, wa)):
            for ib, fb in ((b0, 1 - wb), (b1, wb)):
                for ic, fc in ((c0, 1 - wc), (c1, wc)):
                    out = out + fa * fb * fc * d[ia, ib, ic]
        return out

    def runtime_scale(self):
        """The factor an MDL runtime puts on all light of the file (libbsdf's measured_sample in
        scatter_reflect_transmit mode): the inverse of the largest row albedo of either part, the
        largest channel of the symmetrised data (the SDK's prepare_mbsdfs_part), where it exceeds 1."""
        scale = 1.0
        for part in self.parts:
            largest = max(float(np.max(self.albedo(part, k))) for k in range(self.parts[part].shape[0]))
            scale = min(scale, 1.0 / largest)
        return scale

    def albedo(self, part, k, symmetrise=True):
        """The runtime's albedo of incidence cell k: sum of f over the exit cells times their
        projected solid angle (both azimuth halves)."""
        d = self.table(part, symmetrise)
        n_theta, n_phi = d.shape[0], d.shape[2]
        edges = np.sin(np.arange(n_theta + 1) * (math.pi / 2) / n_theta) ** 2
        return np.einsum("opc,o->c", d[k], np.diff(edges)) * (math.pi / n_phi)
