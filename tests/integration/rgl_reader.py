"""A reader of the RGL material database's `.bsdf` files that does what the renderers do with them.

It follows the format's reference loader, rgl-epfl/brdf-loader's powitacq.inl (from which Mitsuba 3's
and pbrt-v4's `measured` materials come), step by step, and nothing of microbsdf's writer:
- the tensor file parsed and every field's type and shape checked as the loader checks them;
- Marginal2D: bilinear densities on [0,1]^2 with their conditional and marginal CDFs built by the
  trapezoid rule, normalised per slice (vndf, luminance) or kept as they are (ndf, sigma, spectra),
  parameters (phi_i, theta_i[, wavelength]) blended linearly between the file's nodes (find_interval,
  weights clamped to [0, 1]); sample(), invert() and eval() as the loader computes them;
- BRDF::eval(wi, wo) = spectra(vndf.invert(u_m)) * ndf(u_m) / (4 sigma(u_wi)), which a renderer
  takes as f cos(theta_o); BRDF::pdf, the luminance density times the vndf density over the
  Jacobian 2 pi^2 u_m sin(theta_m) 4 (wi . wm); BRDF::sample(u, wi): the luminance warp, then the vndf
  warp, the half vector reflected, weight = eval / pdf (the quantity a path tracer multiplies by).
Everything is vectorised over the exit directions or samples of one incidence."""
import math
import struct

import numpy as np

FLOAT32, UINT8 = 10, 1
ONE_MINUS_EPSILON = 0.999999940395355225  # the loader's clamp of samples away from 0 and 1


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


def find_interval(values, x):
    """The loader's find_interval with pred(i) = values[i] < x (or <= for parameters): the index i
    with pred(i) true and pred(i + 1) false, clamped to [0, len - 2]."""
    return np.clip(np.searchsorted(values, x, side="left") - 1, 0, len(values) - 2)


class Warp:
    """Marginal2D of the loader, its parameters already blended: one slice of data, conditional and
    marginal CDFs (index units, as the loader keeps them)."""

    def __init__(self, data, cond, marg, scale):
        self.data, self.cond, self.marg, self.scale = data, cond, marg, scale
        self.ny, self.nx = data.shape

    def _patch(self, x, y):
        """The bilinear patch (i, j) holding (x, y) and the position in it (tx, ty), as the loader
        finds it (the last patch holds the upper edge)."""
        px = np.asarray(x, float) * (self.nx - 1)
        py = np.asarray(y, float) * (self.ny - 1)
        i = np.minimum(px.astype(np.int64), self.nx - 2)
        j = np.minimum(py.astype(np.int64), self.ny - 2)
        return i, j, px - i, py - j

    def eval(self, x, y):
        i, j, tx, ty = self._patch(x, y)
        d = self.data
        return ((1 - ty) * ((1 - tx) * d[j, i] + tx * d[j, i + 1]) +
                ty * ((1 - tx) * d[j + 1, i] + tx * d[j + 1, i + 1])) * self.scale

    def sample(self, sx, sy):
        """(x, y, pdf) for uniform samples: the row from the marginal CDF, then the column from the
        conditional CDF blended between the row's two ends, each inverting a linear density."""
        sx = np.clip(np.asarray(sx, float), 1 - ONE_MINUS_EPSILON, ONE_MINUS_EPSILON)
        sy = np.clip(np.asarray(sy, float), 1 - ONE_MINUS_EPSILON, ONE_MINUS_EPSILON)
        row = np.clip(np.sum(self.marg[None, :] < sy[:, None], axis=1) - 1, 0, self.ny - 2)
        sy = sy - self.marg[row]
        r0, r1 = self.cond[row, -1], self.cond[row + 1, -1]
        y = _invert_linear(r0, r1, sy)
        sx = sx * ((1 - y) * r0 + y * r1)
        running = (1 - y)[:, None] * self.cond[row] + y[:, None] * self.cond[row + 1]
        col = np.clip(np.sum(running < sx[:, None], axis=1) - 1, 0, self.nx - 2)
        sx = sx - running[np.arange(len(col)), col]
        c0 = (1 - y) * self.data[row, col] + y * self.data[row + 1, col]
        c1 = (1 - y) * self.data[row, col + 1] + y * self.data[row + 1, col + 1]
        x = _invert_linear(c0, c1, sx)
        return ((col + x) / (self.nx - 1), (row + y) / (self.ny - 1),
                ((1 - x) * c0 + x * c1) * (self.nx - 1) * (self.ny - 1))

    def invert(self, x, y):
        """(sx, sy, pdf): the uniform sample that sample() maps to (x, y), and the density there."""
        i, j, tx, ty = self._patch(x, y)
        d = self.data
        c0 = (1 - ty) * d[j, i] + ty * d[j + 1, i]
        c1 = (1 - ty) * d[j, i + 1] + ty * d[j + 1, i + 1]
        pdf = (1 - tx) * c0 + tx * c1
        sx = tx * (c0 + 0.5 * tx * (c1 - c0)) + (1 - ty) * self.cond[j, i] + ty * self.cond[j + 1, i]
        r0, r1 = self.cond[j, -1], self.cond[j + 1, -1]
        sx = sx / ((1 - ty) * r0 + ty * r1)
        sy = ty * (r0 + 0.5 * ty * (r1 - r0)) + self.marg[j]
        return sx, sy, pdf * (self.nx - 1) * (self.ny - 1)


def _invert_linear(a, b, area):
    """t in [0, 1] with a t + (b - a) t^2 / 2 = area, as the loader solves it (a constant density
    where a and b agree to 1e-4)."""
    const = np.abs(a - b) < 1e-4 * (a + b)
    with np.errstate(divide="ignore", invalid="ignore"):
        root = (a - np.sqrt(np.maximum(0.0, a * a - 2 * area * (a - b)))) / (a - b)
        t = np.where(const, 2 * area / (a + b), root)
    return np.nan_to_num(t)


class Marginal2D:
    """The loader's Marginal2D over a stack of slices with parameters: normalised slices (with CDFs)
    or values as they are."""

    def __init__(self, data, params, normalize=True):
        self.params = [np.asarray(p, dtype=np.float64) for p in params]
        self.ny, self.nx = data.shape[-2:]
        assert self.nx >= 2 and self.ny >= 2, "a warp needs >= 2 points per axis"
        shape = [len(p) for p in self.params] + [self.ny, self.nx]
        slices = np.asarray(data, np.float64).reshape(shape)
        self.normalize = normalize
        if not normalize:
            self.data, self.cond, self.marg = slices, None, None
            return
        cond = np.zeros_like(slices)
        cond[..., 1:] = np.cumsum(0.5 * (slices[..., 1:] + slices[..., :-1]), axis=-1)
        marg = np.zeros(slices.shape[:-1])
        marg[..., 1:] = np.cumsum(0.5 * (cond[..., 1:, -1] + cond[..., :-1, -1]), axis=-1)
        total = marg[..., -1:]
        self.data = slices / total[..., None]
        self.cond = cond / total[..., None]
        self.marg = marg / total

    def at(self, *param):
        """The slice the loader's lookup() blends at these parameter values."""
        weights, index = [1.0], [()]
        for values, p in zip(self.params, param):
            if len(values) == 1:
                index = [k + (0,) for k in index]
                continue
            i = int(find_interval(values, np.nextafter(p, np.inf)))  # pred: values[i] <= p
            w1 = float(np.clip((p - values[i]) / (values[i + 1] - values[i]), 0, 1))
            index = [k + (i + d,) for k in index for d in (0, 1)]
            weights = [w * (1 - w1 if d == 0 else w1) for w in weights for d in (0, 1)]
        blend = lambda a: sum(w * a[k] for k, w in zip(index, weights))  # noqa: E731
        if not self.normalize:
            return Warp(blend(self.data), None, None, 1.0)
        return Warp(blend(self.data), blend(self.cond), blend(self.marg), (self.nx - 1) * (self.ny - 1))


def theta2u(theta):
    return np.sqrt(np.asarray(theta) * 2 / math.pi)


def phi2u(phi):
    return (np.asarray(phi) + math.pi) / (2 * math.pi)


def u2theta(u):
    return np.square(u) * (math.pi / 2)


def u2phi(u):
    return (2 * np.asarray(u) - 1) * math.pi


class Incidence:
    """The file seen from one direction wi (towards the light, upper hemisphere): the loader's
    eval, pdf and sample for many exit directions or samples at once."""

    def __init__(self, bsdf, wi):
        self.b, self.wi = bsdf, np.asarray(wi, float) / np.linalg.norm(wi)
        self.theta_i = math.acos(min(1.0, self.wi[2]))
        self.phi_i = math.atan2(self.wi[1], self.wi[0])
        param = (self.phi_i, self.theta_i)
        self.vndf = bsdf.vndf.at(*param)
        self.luminance = bsdf.luminance.at(*param)
        self.spectra = [bsdf.values.at(*param, lam) for lam in bsdf.wavelengths]
        self.sigma = float(bsdf.sigma.at().eval(theta2u(self.theta_i), phi2u(self.phi_i)))

    def _u_m(self, wm):
        theta_m = np.arccos(np.clip(wm[:, 2], -1, 1))
        phi_m = np.arctan2(wm[:, 1], wm[:, 0])
        uy = phi2u(phi_m - self.phi_i if self.b.isotropic else phi_m)
        return theta2u(theta_m), uy - np.floor(uy)

    def _jacobian(self, ux, wm):
        sin_theta_m = np.sqrt(np.maximum(0.0, 1 - wm[:, 2] ** 2))
        return np.maximum(2 * math.pi ** 2 * ux * sin_theta_m, 1e-6) * 4 * (wm @ self.wi)

    def eval(self, wo):
        """BRDF::eval per exit direction (rows) and wavelength (columns): f cos(theta_o)."""
        wo = np.atleast_2d(np.asarray(wo, float))
        wm = self.wi + wo
        wm /= np.linalg.norm(wm, axis=1)[:, None]
        ux, uy = self._u_m(wm)
        sx, sy, _ = self.vndf.invert(ux, uy)
        fr = np.stack([s.eval(sx, sy) for s in self.spectra], axis=1)
        fr *= (self.b.ndf.at().eval(ux, uy) / (4 * self.sigma))[:, None]
        ok = (wo[:, 2] > 0) & (self.wi[2] > 0)
        return np.where(ok[:, None], fr, 0.0)

    def f(self, wo):
        """f = eval / cos(theta_o), as a renderer divides its cosine-weighted eval."""
        wo = np.atleast_2d(np.asarray(wo, float))
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(wo[:, 2:3] > 0, self.eval(wo) / wo[:, 2:3], 0.0)

    def pdf(self, wo):
        wo = np.atleast_2d(np.asarray(wo, float))
        wm = self.wi + wo
        wm /= np.linalg.norm(wm, axis=1)[:, None]
        ux, uy = self._u_m(wm)
        sx, sy, vndf_pdf = self.vndf.invert(ux, uy)
        pdf = vndf_pdf * self.luminance.eval(sx, sy) / self._jacobian(ux, wm)
        return np.where(wo[:, 2] > 0, pdf, 0.0)

    def sample(self, u1, u2):
        """BRDF::sample for uniform (u1, u2): (wo, pdf, weight = eval / pdf per wavelength); a
        direction below the horizon has weight 0."""
        lx, ly, lum_pdf = self.luminance.sample(np.asarray(u2, float), np.asarray(u1, float))
        ux, uy, ndf_pdf = self.vndf.sample(lx, ly)
        phi_m = u2phi(uy) + (self.phi_i if self.b.isotropic else 0.0)
        theta_m = u2theta(ux)
        wm = np.stack([np.cos(phi_m) * np.sin(theta_m), np.sin(phi_m) * np.sin(theta_m), np.cos(theta_m)], axis=1)
        wo = 2 * (wm @ self.wi)[:, None] * wm - self.wi
        fr = np.stack([s.eval(lx, ly) for s in self.spectra], axis=1)
        fr *= (self.b.ndf.at().eval(ux, uy) / (4 * self.sigma))[:, None]
        pdf = ndf_pdf * lum_pdf / self._jacobian(ux, wm)
        ok = (wo[:, 2] > 0) & (pdf > 0)
        with np.errstate(divide="ignore", invalid="ignore"):
            weight = np.where(ok[:, None], fr / pdf[:, None], 0.0)
        return wo, np.where(ok, pdf, 0.0), weight


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
        # The loader's structure checks (types, ranks, shapes that must agree).
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
            self.wavelengths = np.arange(3.0)  # Mitsuba 3 passes the channel index as the wavelength
        for k in ("ndf", "sigma", "vndf", "luminance"):
            assert np.all(np.isfinite(f[k])) and np.all(f[k] >= 0), f"{k}: negative or not finite"
        assert np.all(np.isfinite(values)) and np.all(values >= 0), "values negative or not finite"
        assert np.all(np.diff(f["theta_i"]) > 0), "theta_i not ascending"
        self.description = bytes(f["description"]).decode()
        assert f["jacobian"][0] == 1, "the readers apply ndf / (4 sigma) only with jacobian = 1"
        self.isotropic = n_phi <= 2
        if not self.isotropic:
            span = f["phi_i"][-1] - f["phi_i"][0]
            assert round(2 * math.pi / span) == 1, "the reference loader handles a full azimuth range only"
        self.fields = f
        self.ndf = Marginal2D(f["ndf"], [], normalize=False)
        self.sigma = Marginal2D(f["sigma"], [], normalize=False)
        params = [f["phi_i"], f["theta_i"]]
        self.vndf = Marginal2D(f["vndf"], params)
        self.luminance = Marginal2D(f["luminance"], params)
        self.values = Marginal2D(values, params + [self.wavelengths], normalize=False)

    def incidence(self, wi):
        return Incidence(self, wi)

    def f(self, wi, wo):
        """f(wi -> wo) per wavelength (or RGB channel) of one pair, as a renderer gets it."""
        if wi[2] <= 0 or wo[2] <= 0:
            return np.zeros(len(self.wavelengths))
        return self.incidence(wi).f(wo)[0]

    def furnace(self, wi, n=96, seed=0):
        """The white-furnace albedo a path tracer sees: the mean of BRDF::sample's weights over n x n
        jittered stratified samples, per wavelength, and the standard error of that mean (from the
        spread of the weights; an upper bound for stratified samples)."""
        rng = np.random.default_rng(seed)
        a, b = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
        u1 = (a.reshape(-1) + rng.random(n * n)) / n
        u2 = (b.reshape(-1) + rng.random(n * n)) / n
        _, _, weight = self.incidence(wi).sample(u1, u2)
        return weight.mean(axis=0), weight.std(axis=0) / math.sqrt(n * n)
