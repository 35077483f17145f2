"""An independent reader of the RGL material database's `.bsdf` files, written from the format's
description (Dupuy & Jakob 2018, "An Adaptive Parameterization for Efficient Material Acquisition and
Rendering", and the loaders of Mitsuba 3 and pbrt-v4 that read it), for the export tests.

It parses the tensor file, checks every field's type and shape as those loaders do, and evaluates f
the way they do: the half vector's unit coordinates u = (sqrt(2 theta / pi), (phi + pi) / 2 pi)
(relative to the incidence azimuth in an isotropic file), the vndf warp inverted to find the spectra
table's coordinates, and f cos(theta_i) = spectra * ndf / (4 sigma), with parameters (phi_i,
theta_i[, wavelength]) interpolated linearly between the file's nodes."""
import math
import struct

import numpy as np

FLOAT32, UINT8 = 10, 1


def parse_tensor_file(path):
    with open(path, "rb") as f:
        raw = f.read()
    assert len(raw) >= 18, "too small"
    assert raw[:12] == b"tensor_file\0", "bad magic"
    assert raw[12] == 1 and raw[13] == 0, f"version {raw[12]}.{raw[13]}"
    (n_fields,) = struct.unpack_from("<I", raw, 14)
    pos, fields = 18, {}
    for _ in range(n_fields):
        (name_len,) = struct.unpack_from("<H", raw, pos)
        pos += 2
        name = raw[pos:pos + name_len].decode()
        pos += name_len
        ndim, dtype, offset = struct.unpack_from("<HBQ", raw, pos)
        pos += 11
        shape = struct.unpack_from(f"<{ndim}Q", raw, pos)
        pos += 8 * ndim
        assert dtype in (FLOAT32, UINT8), f"{name}: type {dtype}"
        count = int(np.prod(shape)) if ndim else 1
        np_type = np.float32 if dtype == FLOAT32 else np.uint8
        assert offset + count * np.dtype(np_type).itemsize <= len(raw), f"{name}: data beyond the file's end"
        fields[name] = (dtype, np.frombuffer(raw, np_type, count, offset).reshape(shape))
    return fields


class Marginal2D:
    """The continuous marginal/conditional warp of a bilinear density on [0,1]^2, with parameters
    interpolated linearly (the construction of Dupuy & Jakob 2018, Sec. 5)."""

    def __init__(self, data, params, normalize=True):
        self.params = [np.asarray(p, dtype=np.float64) for p in params]
        self.ny, self.nx = data.shape[-2:]
        assert self.nx >= 2 and self.ny >= 2, "a warp needs >= 2 points per axis"
        slices = data.reshape(-1, self.ny, self.nx).astype(np.float64)
        self.data, self.cond, self.marg = [], [], []
        for s in slices:
            cond = np.zeros_like(s)
            cond[:, 1:] = np.cumsum(0.5 * (s[:, 1:] + s[:, :-1]), axis=1)
            marg = np.zeros(self.ny)
            marg[1:] = np.cumsum(0.5 * (cond[1:, -1] + cond[:-1, -1]))
            scale = 1.0 / marg[-1] if normalize else (1.0 / ((self.nx - 1) * (self.ny - 1)))
            self.data.append(s * scale)
            self.cond.append(cond * scale)
            self.marg.append(marg * scale)
        self.data, self.cond, self.marg = map(np.array, (self.data, self.cond, self.marg))

    def _blend(self, param):
        weights = np.ones(1)
        index = np.zeros(1, dtype=int)
        for values, p in zip(self.params, param):
            if len(values) == 1:
                index = index * 1
                continue
            i = int(np.clip(np.searchsorted(values, p, side="left") - 1, 0, len(values) - 2))
            w1 = float(np.clip((p - values[i]) / (values[i + 1] - values[i]), 0, 1))
            index = np.concatenate([index * len(values) + i, index * len(values) + i + 1])
            weights = np.concatenate([weights * (1 - w1), weights * w1])
        return (sum(w * self.data[k] for k, w in zip(index, weights)),
                sum(w * self.cond[k] for k, w in zip(index, weights)),
                sum(w * self.marg[k] for k, w in zip(index, weights)))

    def eval(self, x, y, param=()):
        data, _, _ = self._blend(param)
        px, py = np.clip(x, 0, 1) * (self.nx - 1), np.clip(y, 0, 1) * (self.ny - 1)
        i, j = min(int(px), self.nx - 2), min(int(py), self.ny - 2)
        tx, ty = px - i, py - j
        return ((1 - ty) * ((1 - tx) * data[j, i] + tx * data[j, i + 1]) +
                ty * ((1 - tx) * data[j + 1, i] + tx * data[j + 1, i + 1])) * (self.nx - 1) * (self.ny - 1)

    def sample(self, u, v, param=()):
        """The point a uniform sample (u, v) maps to, and the density there: the row from the
        marginal (linear between the rows' integrals), then the column from the conditional
        interpolated between the two rows; each step inverts a linear density in closed form."""
        data, cond, marg = self._blend(param)
        eps = float(np.finfo(np.float32).eps)
        u, v = min(max(u, eps), 1 - eps), min(max(v, eps), 1 - eps)

        def linear_root(a, b, area):  # a t + (b - a) t^2 / 2 = area on [0, 1]
            den = a + math.sqrt(max(0.0, a * a + 2 * area * (b - a)))
            return 2 * area / den if den > 0 else 0.0

        j = int(np.clip(np.searchsorted(marg, v, side="left") - 1, 0, self.ny - 2))
        r0, r1 = cond[j, -1], cond[j + 1, -1]
        ty = linear_root(r0, r1, v - marg[j])
        target = u * ((1 - ty) * r0 + ty * r1)
        running = (1 - ty) * cond[j] + ty * cond[j + 1]
        i = int(np.clip(np.searchsorted(running, target, side="left") - 1, 0, self.nx - 2))
        c0 = (1 - ty) * data[j, i] + ty * data[j + 1, i]
        c1 = (1 - ty) * data[j, i + 1] + ty * data[j + 1, i + 1]
        tx = linear_root(c0, c1, target - running[i])
        pdf = ((1 - tx) * c0 + tx * c1) * (self.nx - 1) * (self.ny - 1)
        return (i + tx) / (self.nx - 1), (j + ty) / (self.ny - 1), pdf

    def invert(self, x, y, param=()):
        """The unit-square sample that the warp maps to the point (x, y)."""
        data, cond, marg = self._blend(param)
        px, py = np.clip(x, 0, 1) * (self.nx - 1), np.clip(y, 0, 1) * (self.ny - 1)
        i, j = min(int(px), self.nx - 2), min(int(py), self.ny - 2)
        tx, ty = px - i, py - j
        c0 = (1 - ty) * data[j, i] + ty * data[j + 1, i]
        c1 = (1 - ty) * data[j, i + 1] + ty * data[j + 1, i + 1]
        r0, r1 = cond[j, -1], cond[j + 1, -1]
        u = tx * (c0 + 0.5 * tx * (c1 - c0)) + (1 - ty) * cond[j, i] + ty * cond[j + 1, i]
        u /= (1 - ty) * r0 + ty * r1
        v = ty * (r0 + 0.5 * ty * (r1 - r0)) + marg[j]
        return u, v


def theta2u(theta):
    return math.sqrt(theta * 2 / math.pi)


def phi2u(phi):
    return (phi + math.pi) / (2 * math.pi)


class RglBsdf:
    def __init__(self, path):
        fields = parse_tensor_file(path)
        need = ["description", "jacobian", "theta_i", "phi_i", "ndf", "sigma", "vndf", "luminance"]
        for name in need:
            assert name in fields, f"missing field {name}"
        spectral = "spectra" in fields
        assert spectral or "rgb" in fields, "neither spectra nor rgb"
        ty = {k: t for k, (t, _) in fields.items()}
        f = {k: v for k, (_, v) in fields.items()}
        # The loaders' structure checks (types, ranks, shapes that must agree).
        assert ty["description"] == UINT8 and f["description"].ndim == 1
        assert ty["jacobian"] == UINT8 and f["jacobian"].shape == (1,)
        for k in ("theta_i", "phi_i", "ndf", "sigma", "vndf", "luminance"):
            assert ty[k] == FLOAT32, f"{k} is not float32"
        assert f["theta_i"].ndim == 1 and f["phi_i"].ndim == 1
        assert f["ndf"].ndim == 2 and f["sigma"].ndim == 2
        n_phi, n_theta = len(f["phi_i"]), len(f["theta_i"])
        assert f["vndf"].ndim == 4 and f["vndf"].shape[:2] == (n_phi, n_theta)
        lum = f["luminance"]
        assert lum.ndim == 4 and lum.shape[:2] == (n_phi, n_theta) and lum.shape[2] == lum.shape[3]
        values = f["spectra"] if spectral else f["rgb"]
        assert values.ndim == 5 and values.shape[:2] == (n_phi, n_theta) and values.shape[3] == values.shape[4]
        assert values.shape[3:] == lum.shape[2:]
        if spectral:
            assert ty["wavelengths"] == FLOAT32 and f["wavelengths"].shape == (values.shape[2],)
            self.wavelengths = f["wavelengths"].astype(float)
        else:
            assert values.shape[2] == 3
            self.wavelengths = np.arange(3.0)  # the channel index stands for the wavelength
        for k in ("ndf", "sigma", "vndf", "luminance"):
            assert np.all(np.isfinite(f[k])) and np.all(f[k] >= 0), f"{k}: negative or not finite"
        assert np.all(np.isfinite(values)) and np.all(values >= 0), "values negative or not finite"
        assert np.all(np.diff(f["theta_i"]) > 0), "theta_i not ascending"
        self.description = bytes(f["description"]).decode()
        self.jacobian = bool(f["jacobian"][0])
        self.isotropic = n_phi <= 2
        if not self.isotropic:
            span = f["phi_i"][-1] - f["phi_i"][0]
            assert round(2 * math.pi / span) == 1, "this reader handles a full azimuth range only"
        self.fields = f
        self.ndf = Marginal2D(f["ndf"], [], normalize=False)
        self.sigma = Marginal2D(f["sigma"], [], normalize=False)
        params = [f["phi_i"], f["theta_i"]]
        self.vndf = Marginal2D(f["vndf"], params)
        self.luminance = Marginal2D(f["luminance"], params)
        self.values = Marginal2D(values, params + [self.wavelengths], normalize=False)

    def albedo(self, wi, n=64):
        """Integral of f cos(theta_o) over the upper hemisphere for light from wi, estimated as a
        renderer would: stratified samples of the vndf warp (n x n), each reflected about its half
        vector, weighted by f cos / pdf with pdf = vndf pdf / (2 pi^2 u sin(theta_m) 4 wi.m)."""
        wi = np.asarray(wi, float)
        theta_i, phi_i = math.acos(min(1.0, wi[2])), math.atan2(wi[1], wi[0])
        total = np.zeros(len(self.wavelengths))
        for a in range(n):
            for b in range(n):
                x, y, pdf = self.vndf.sample((b + 0.5) / n, (a + 0.5) / n, (phi_i, theta_i))
                theta_m, phi_m = x * x * math.pi / 2, (2 * y - 1) * math.pi + (phi_i if self.isotropic else 0)
                m = np.array([math.sin(theta_m) * math.cos(phi_m), math.sin(theta_m) * math.sin(phi_m), math.cos(theta_m)])
                c = float(np.dot(wi, m))
                wo = 2 * c * m - wi
                jac = 2 * math.pi ** 2 * x * math.sin(theta_m) * 4 * c
                if c <= 0 or wo[2] <= 0 or pdf <= 0 or jac <= 1e-12:
                    continue
                total += self.f(wi, wo) * wo[2] * jac / pdf
        return total / (n * n)

    def f(self, wi, wo):
        """f(wi -> wo) per wavelength (or RGB channel), wi towards the light; 0 below the horizon."""
        wi, wo = np.asarray(wi, float), np.asarray(wo, float)
        if wi[2] <= 0 or wo[2] <= 0:
            return np.zeros(len(self.wavelengths))
        wm = (wi + wo) / np.linalg.norm(wi + wo)
        theta_i, phi_i = math.acos(min(1.0, wi[2])), math.atan2(wi[1], wi[0])
        theta_m, phi_m = math.acos(min(1.0, wm[2])), math.atan2(wm[1], wm[0])
        u_wi = (theta2u(theta_i), phi2u(phi_i))
        um_y = phi2u(phi_m - phi_i if self.isotropic else phi_m)
        u_wm = (theta2u(theta_m), um_y - math.floor(um_y))
        s = self.vndf.invert(*u_wm, (phi_i, theta_i))
        spec = np.array([self.values.eval(*s, (phi_i, theta_i, lam)) for lam in self.wavelengths])
        if self.jacobian:
            spec = spec * self.ndf.eval(*u_wm) / (4 * self.sigma.eval(*u_wi))
        return spec / math.cos(theta_i)
