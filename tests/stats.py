"""Statistical test helpers: Pearson chi² goodness of fit for warps/BSDFs and a Z-test for means.

A numpy port of the idea of Mitsuba 3's ``src/python/python/chi2.py`` (``ChiSquareTest``)
and pbrt-v4's ``bsdfs_test.cpp`` chi² test:

1. Draw ``n_samples`` points with the sampling routine and histogram the *valid* ones on a
   regular grid over a 2D parameterization of the domain (sphere: (s, φ) with
   1 − cosθ = 2 s^zoom around a chosen pole; plane: an axis-aligned box).
2. Integrate the claimed pdf over every cell (tensor Gauss–Legendre per cell, refined
   adaptively 2×2 where the estimate is unstable, like pbrt's adaptive Simpson) and
   multiply by ``n_samples``: expected counts. Invalid samples are simply not counted, so
   a pdf integrating to less than 1 is fine as long as it matches the valid fraction.
3. Reject if: a valid sample is not finite / outside the domain; the pdf is negative; the
   pdf integrates to more than 1.01; more than n·1e-5 samples fall in cells with zero
   expected count (pbrt's rounding tolerance).
4. Pool the cells with expected count < 5 ("normality assumptions break down", pbrt), compute
   Pearson's statistic χ² = Σ (O − E)²/E with dof = #bins − 1 and the p-value
   Q(dof/2, χ²/2) (regularized upper incomplete gamma); pass if p >= the Šidák-corrected
   level 1 − (1 − significance)^(1/test_count).

``zoom > 1`` concentrates the sphere grid's resolution near its pole; tests point the pole
at a sharp lobe (e.g. the mirror direction of a roughness-0 GGX lobe) so that the lobe is
resolved by several rows of cells.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import numpy as np
from numpy.typing import NDArray
from scipy.special import erfc, gammaincc

F64 = NDArray[np.float64]

#: Points per pdf evaluation call (bounds the memory of the quadrature).
_CHUNK = 1 << 18


# ---------------------------------------------------------------------------------------
# Domains: a box of parameters (x, y) ↔ points, with the Jacobian d(point measure)/dx dy
# ---------------------------------------------------------------------------------------

@dataclass(frozen=True)
class SphericalDomain:
    """Unit sphere parameterized by (s, φ) ∈ [0, 1] × [−π, π].

    The direction is ``frame.T @ (sinθ cosφ, sinθ sinφ, cosθ)`` with 1 − cosθ = 2 s^zoom, so
    s = 0 is the pole ``frame[2]`` and s = 1 its antipode; zoom = 1 is Mitsuba's uniform
    (cosθ, φ) grid. Jacobian dω/(ds dφ) = 2·zoom·s^(zoom − 1).

    Attributes:
        frame: (3, 3) orthonormal rows (t, b, n); n is the pole.
        zoom: >= 1.
    """

    frame: F64 = field(default_factory=lambda: np.eye(3))
    zoom: float = 1.0

    @property
    def bounds(self) -> tuple[tuple[float, float], tuple[float, float]]:
        return (0.0, 1.0), (-np.pi, np.pi)

    def to_points(self, xy: F64) -> F64:
        """(M, 2) parameters → (M, 3) unit directions."""
        sk = xy[:, 0] ** self.zoom  # (1 − cosθ)/2
        cos_t = 1.0 - 2.0 * sk
        sin_t = 2.0 * np.sqrt(np.clip(sk * (1.0 - sk), 0.0, None))
        local = np.stack([sin_t * np.cos(xy[:, 1]), sin_t * np.sin(xy[:, 1]), cos_t], axis=1)
        return local @ np.asarray(self.frame, np.float64)

    def jacobian(self, xy: F64) -> F64:
        """dω / (ds dφ), (M,)."""
        return 2.0 * self.zoom * xy[:, 0] ** (self.zoom - 1.0)

    def from_points(self, w: F64) -> F64:
        """(M, 3) unit directions → (M, 2) parameters."""
        frame = np.asarray(self.frame, np.float64)
        local = w @ frame.T
        # (1 − cosθ)/2 = |w − n|²/4: accurate near the pole
        d = w - frame[2]
        half_one_minus_cos = np.clip(np.einsum("ij,ij->i", d, d) * 0.25, 0.0, 1.0)
        s = half_one_minus_cos ** (1.0 / self.zoom)
        return np.stack([s, np.arctan2(local[:, 1], local[:, 0])], axis=1)

    def is_valid_point(self, w: F64) -> NDArray[np.bool_]:
        """Finite unit vectors."""
        ok = np.all(np.isfinite(w), axis=1)
        norm = np.sqrt(np.einsum("ij,ij->i", np.where(ok[:, None], w, 0.0), np.where(ok[:, None], w, 0.0)))
        return ok & (np.abs(norm - 1.0) < 1e-6)


@dataclass(frozen=True)
class PlanarDomain:
    """Axis-aligned box ``bounds = ((x0, x1), (y0, y1))``; points are the parameters."""

    bounds: tuple[tuple[float, float], tuple[float, float]] = ((0.0, 1.0), (0.0, 1.0))

    def to_points(self, xy: F64) -> F64:
        return xy

    def jacobian(self, xy: F64) -> F64:
        return np.ones(xy.shape[0])

    def from_points(self, p: F64) -> F64:
        return p

    def is_valid_point(self, p: F64) -> NDArray[np.bool_]:
        (x0, x1), (y0, y1) = self.bounds
        ok = np.all(np.isfinite(p), axis=1)
        p = np.where(ok[:, None], p, 0.0)
        return ok & (p[:, 0] >= x0) & (p[:, 0] <= x1) & (p[:, 1] >= y0) & (p[:, 1] <= y1)


Domain = SphericalDomain | PlanarDomain


def frame_from_pole(pole: F64) -> F64:
    """(3, 3) orthonormal rows (t, b, n) with n = normalized ``pole``."""
    n = np.asarray(pole, np.float64) / np.linalg.norm(pole)
    helper = np.array([1.0, 0.0, 0.0]) if abs(n[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    t = np.cross(helper, n)
    t /= np.linalg.norm(t)
    return np.stack([t, np.cross(n, t), n])


# ---------------------------------------------------------------------------------------
# Cell integration: tensor Gauss–Legendre, adaptive 2×2 refinement
# ---------------------------------------------------------------------------------------

def _gauss_cells(density: Callable[[F64], F64], x0: F64, x1: F64, y0: F64, y1: F64,
                 n_gauss: int) -> F64:
    """∫∫ density over each of C boxes with an n×n Gauss–Legendre rule. Returns (C,)."""
    nodes, weights = np.polynomial.legendre.leggauss(n_gauss)
    out = np.empty(x0.shape[0])
    per_chunk = max(1, _CHUNK // (n_gauss * n_gauss))
    for lo in range(0, x0.shape[0], per_chunk):
        sl = slice(lo, lo + per_chunk)
        xs = 0.5 * (x0[sl] + x1[sl])[:, None] + 0.5 * (x1[sl] - x0[sl])[:, None] * nodes
        ys = 0.5 * (y0[sl] + y1[sl])[:, None] + 0.5 * (y1[sl] - y0[sl])[:, None] * nodes
        c = xs.shape[0]
        X = np.broadcast_to(xs[:, :, None], (c, n_gauss, n_gauss))
        Y = np.broadcast_to(ys[:, None, :], (c, n_gauss, n_gauss))
        vals = density(np.stack([X.ravel(), Y.ravel()], axis=1)).reshape(c, n_gauss, n_gauss)
        area = 0.25 * (x1[sl] - x0[sl]) * (y1[sl] - y0[sl])
        out[sl] = area * np.einsum("cij,i,j->c", vals, weights, weights)
    return out


def integrate_cells(density: Callable[[F64], F64], x_edges: F64, y_edges: F64,
                    abs_tol: Callable[[F64], F64], n_gauss: int = 4,
                    max_depth: int = 7) -> F64:
    """Integrate ``density`` over every grid cell, refining unstable cells 2×2.

    A cell is accepted when its n×n Gauss estimate and the sum of its four children's
    estimates differ by at most its tolerance; otherwise each child is refined with half
    the tolerance (so the error along a discontinuity curve shrinks with depth).

    Args:
        density: (M, 2) parameters → (M,) density in parameter measure.
        x_edges, y_edges: (Rx+1,), (Ry+1,) cell edges.
        abs_tol: (C,) first estimates → (C,) absolute tolerances.
    Returns:
        (Rx, Ry) cell integrals.
    """
    X0, Y0 = np.meshgrid(x_edges[:-1], y_edges[:-1], indexing="ij")
    X1, Y1 = np.meshgrid(x_edges[1:], y_edges[1:], indexing="ij")
    x0, x1, y0, y1 = X0.ravel(), X1.ravel(), Y0.ravel(), Y1.ravel()
    est = _gauss_cells(density, x0, x1, y0, y1, n_gauss)
    tol = abs_tol(est)
    owner = np.arange(est.size)
    result = np.zeros(est.size)
    for _ in range(max_depth):
        if owner.size == 0:
            break
        # Children boxes, 4 per active box, ordered (lower-left, lower-right, upper-left, upper-right)
        xm, ym = 0.5 * (x0 + x1), 0.5 * (y0 + y1)
        cx0 = np.stack([x0, xm, x0, xm], axis=1).ravel()
        cx1 = np.stack([xm, x1, xm, x1], axis=1).ravel()
        cy0 = np.stack([y0, y0, ym, ym], axis=1).ravel()
        cy1 = np.stack([ym, ym, y1, y1], axis=1).ravel()
        child = _gauss_cells(density, cx0, cx1, cy0, cy1, n_gauss)
        fine = child.reshape(-1, 4).sum(axis=1)
        done = np.abs(fine - est) <= tol
        np.add.at(result, owner[done], fine[done])
        again = np.repeat(~done, 4)
        owner = np.repeat(owner, 4)[again]
        tol = np.repeat(0.5 * tol, 4)[again]
        est = child[again]
        x0, x1, y0, y1 = cx0[again], cx1[again], cy0[again], cy1[again]
    np.add.at(result, owner, est)
    return result.reshape(X0.shape)


def _domain_density(domain: Domain, pdf_func: Callable[[F64], F64]) -> Callable[[F64], F64]:
    """pdf in parameter measure: pdf(point(xy))·Jacobian(xy)."""
    def density(xy: F64) -> F64:
        pdf = np.asarray(pdf_func(domain.to_points(xy)), np.float64).reshape(-1)
        return pdf * domain.jacobian(xy)
    return density


def _edges(domain: Domain, res: tuple[int, int]) -> tuple[F64, F64]:
    (x0, x1), (y0, y1) = domain.bounds
    return np.linspace(x0, x1, res[0] + 1), np.linspace(y0, y1, res[1] + 1)


def integrate_pdf(pdf_func: Callable[[F64], F64], domain: Domain | None = None,
                  res: tuple[int, int] = (51, 101), n_gauss: int = 4, max_depth: int = 7,
                  rel_tol: float = 1e-6) -> float:
    """∫ pdf over the whole domain (adaptive cell quadrature); ≈ 1 for a normalized pdf.

    ``rel_tol`` is the per-cell absolute tolerance divided by the cell count.
    """
    domain = SphericalDomain() if domain is None else domain
    xe, ye = _edges(domain, res)
    n_cells = res[0] * res[1]
    table = integrate_cells(_domain_density(domain, pdf_func), xe, ye,
                            lambda e: np.full(e.shape, rel_tol / n_cells), n_gauss, max_depth)
    return float(table.sum())


# ---------------------------------------------------------------------------------------
# Pearson statistic with pooling
# ---------------------------------------------------------------------------------------

def sidak_level(significance: float, test_count: int) -> float:
    """Per-test level so that ``test_count`` independent tests have family level ``significance``."""
    return 1.0 - (1.0 - significance) ** (1.0 / max(int(test_count), 1))


def chi2_from_tables(observed: F64, expected: F64, n_samples: int, significance: float = 0.01,
                     test_count: int = 1, min_expected: float = 5.0) -> tuple[bool, str, float]:
    """Pearson chi² of observed vs expected counts, with pooling and Šidák correction.

    Args:
        observed, expected: same-shape count tables (expected may be fractional).
        n_samples: number of samples drawn (for the zero-expected-cell tolerance n·1e-5).
    Returns:
        (passed, message, p_value).
    """
    obs = np.asarray(observed, np.float64).ravel()
    exp = np.asarray(expected, np.float64).ravel()
    # Samples where the pdf claims nothing can land (pbrt tolerance for rounding)
    zero = exp <= 0.0
    stray = obs[zero].sum()
    if stray > n_samples * 1e-5:
        return False, f"{int(stray)} samples in cells with zero expected count", 0.0
    obs, exp = obs[~zero], exp[~zero]
    order = np.argsort(exp, kind="stable")
    obs, exp = obs[order], exp[order]
    # Pool the cells with expected < min_expected; if the pool itself is still below the
    # threshold, merge the next (smallest remaining) cell into it
    n_small = int(np.searchsorted(exp, min_expected, side="left"))
    if 0 < exp[:n_small].sum() < min_expected and n_small < exp.size:
        n_small += 1
    pooled_obs, pooled_exp = obs[:n_small].sum(), exp[:n_small].sum()
    obs, exp = obs[n_small:], exp[n_small:]
    chi2 = float(np.sum((obs - exp) ** 2 / exp))
    dof = exp.size
    if pooled_exp > 0.0:
        chi2 += (pooled_obs - pooled_exp) ** 2 / pooled_exp
        dof += 1
    dof -= 1
    if dof <= 0:
        return False, f"too few cells for a chi² test (dof = {dof})", 0.0
    p_value = float(gammaincc(0.5 * dof, 0.5 * chi2))
    level = sidak_level(significance, test_count)
    msg = f"chi2 = {chi2:.1f}, dof = {dof}, p = {p_value:.4g}, level = {level:.3g}"
    return p_value >= level, msg, p_value


# ---------------------------------------------------------------------------------------
# The test driver
# ---------------------------------------------------------------------------------------

def _draw(sample_func: Callable, n_samples: int, sample_dim: int,
          rng: np.random.Generator) -> tuple[F64, NDArray[np.bool_]]:
    """Call ``sample_func`` in chunks; returns (points, valid)."""
    pts, valid = [], []
    for lo in range(0, n_samples, _CHUNK):
        u = rng.random((min(_CHUNK, n_samples - lo), sample_dim))
        out = sample_func(u)
        p, v = out if isinstance(out, tuple) else (out, np.ones(u.shape[0], bool))
        pts.append(np.asarray(p, np.float64))
        valid.append(np.asarray(v, bool).reshape(-1))
    return np.concatenate(pts), np.concatenate(valid)


def _reintegrate_missed(density: Callable[[F64], F64], xe: F64, ye: F64,
                        tol: Callable[[F64], F64], observed: F64, expected: F64,
                        n_samples: int, n_gauss: int, max_depth: int,
                        sub_res: int = 16, max_cells: int = 64) -> None:
    """Re-integrate, on a sub_res² sub-grid, the cells with samples but zero expected count.

    A thin sliver of support (e.g. cut by the horizon) can fall between all quadrature
    nodes of a cell and of its children, so the adaptive rule never sees it. The sample
    histogram tells where to look harder; a pdf that is really zero there stays zero, so
    this cannot hide a wrong pdf. Updates ``expected`` in place.
    """
    missed = np.argwhere((expected <= 0.0) & (observed > 0.0))
    for i, j in missed[:max_cells]:
        sub_x = np.linspace(xe[i], xe[i + 1], sub_res + 1)
        sub_y = np.linspace(ye[j], ye[j + 1], sub_res + 1)
        table = integrate_cells(density, sub_x, sub_y, tol, n_gauss, max_depth)
        expected[i, j] = table.sum() * n_samples


def chi2_test(sample_func: Callable, pdf_func: Callable[[F64], F64], n_samples: int = 1_000_000,
              res_theta: int = 51, res_phi: int = 101, significance: float = 0.01,
              test_count: int = 1, seed: int = 0, sample_dim: int = 2,
              domain: Domain | None = None, n_gauss: int = 4,
              max_depth: int = 7) -> tuple[bool, str]:
    """Chi² test that ``sample_func`` draws points with density ``pdf_func``.

    Args:
        sample_func: (n, sample_dim) uniforms → points (n, 3) [sphere] or (n, 2) [plane],
            or a tuple (points, valid (n,) bool); invalid samples are not counted.
        pdf_func: (M, 3) or (M, 2) points → (M,) pdf in the domain's measure
            (solid angle on the sphere, area on the plane).
        n_samples: samples drawn (valid or not); expected counts are n_samples·∫cell pdf.
        res_theta, res_phi: grid resolution along the domain's first/second parameter
            (odd by default, as in Mitsuba, so no cell edge falls on a symmetry plane).
        significance, test_count: family significance and number of tests (Šidák).
        seed: seed of the PCG64 generator for the uniforms.
        domain: :class:`SphericalDomain` (default) or :class:`PlanarDomain`.
        n_gauss, max_depth: cell quadrature order and maximum refinement depth.
    Returns:
        (passed, message).
    """
    domain = SphericalDomain() if domain is None else domain
    rng = np.random.default_rng(seed)
    points, valid = _draw(sample_func, n_samples, sample_dim, rng)
    # Valid samples must be finite points of the domain
    bad = valid & ~domain.is_valid_point(points)
    if bad.any():
        return False, f"{int(bad.sum())} valid samples are not finite points of the domain"
    # Observed histogram of the valid samples
    xe, ye = _edges(domain, (res_theta, res_phi))
    xy = domain.from_points(points[valid])
    observed, _, _ = np.histogram2d(np.clip(xy[:, 0], xe[0], xe[-1]),
                                    np.clip(xy[:, 1], ye[0], ye[-1]), bins=[xe, ye])
    # Expected counts: per-cell pdf integral × n. The refinement tolerance is 10 % of the
    # cell's Poisson standard deviation √E, so quadrature error adds <= ~0.01 per cell to χ²
    # (vs. a statistic whose standard deviation is √(2·dof) ≈ 70 for 2500 cells)
    density = _domain_density(domain, pdf_func)
    neg = []

    def checked(xy_: F64) -> F64:
        d = density(xy_)
        if np.any(~np.isfinite(d)) or np.any(d < 0.0):
            neg.append(True)
        return np.where(np.isfinite(d), d, 0.0)

    tol = lambda e: 0.1 * np.sqrt(np.maximum(e * n_samples, 1.0)) / n_samples  # noqa: E731
    expected = integrate_cells(checked, xe, ye, tol, n_gauss, max_depth) * n_samples
    _reintegrate_missed(checked, xe, ye, tol, observed, expected, n_samples, n_gauss, max_depth)
    if neg:
        return False, "pdf_func returned a negative or non-finite value"
    integral = expected.sum() / n_samples
    head = f"pdf integral = {integral:.5f}, valid = {int(valid.sum())}/{n_samples}"
    if integral > 1.01:
        return False, f"{head}: the pdf integrates to more than 1.01"
    passed, msg, _ = chi2_from_tables(observed, expected, n_samples, significance, test_count)
    return passed, f"{head}, {msg}"


def z_test_mean(samples: F64, expected: float | F64, axis: int = 0) -> F64:
    """Two-sided Z-test that the mean of ``samples`` equals ``expected``.

    z = (mean − expected)/(s/√n) with the sample standard deviation s (ddof = 1), valid for
    large n by the central limit theorem. A zero-variance sample gives p = 1 if its mean
    equals ``expected`` to 1e-12 relative, else 0.

    Args:
        samples: (n, ...) i.i.d. estimates along ``axis``.
        expected: scalar or array broadcastable to the mean.
    Returns:
        p-value(s) erfc(|z|/√2), shape of the mean.
    """
    x = np.asarray(samples, np.float64)
    n = x.shape[axis]
    mean = x.mean(axis=axis)
    se = x.std(axis=axis, ddof=1) / np.sqrt(n)
    diff = np.abs(mean - np.asarray(expected, np.float64))
    exact = diff <= 1e-12 * np.maximum(np.abs(mean), 1.0)
    z = np.divide(diff, se, out=np.full(np.shape(diff), np.inf), where=se > 0)
    return np.where(se > 0, erfc(z / np.sqrt(2.0)), np.where(exact, 1.0, 0.0))


# ---------------------------------------------------------------------------------------
# Two renderers, several seeds each: block means compared by their own noise
# ---------------------------------------------------------------------------------------

@dataclass
class ImageComparison:
    """Result of :func:`compare_images` (RGB channels; B blocks with noise).

    Attributes:
        z: (By, Bx, 3) normal-equivalent z-scores of the block-mean differences (0 where
            both renderers are noise-free and equal, e.g. the background).
        chi2: (3,) Σ z² per channel over its ``blocks``; ``blocks`` (3,) counts them.
        p_chi2: (3,) upper tail of χ²(blocks) per channel.
        p_max: family p-value of the largest |z| (Šidák over all block channels).
        deff: (2,) variance inflation of (ours, ref) from correlated pixel noise (≥ 1).
        mean_ours, mean_ref: (3,) image means.
        passed: both statistics above the significance level.
    """

    z: F64
    chi2: F64
    blocks: NDArray[np.int64]
    p_chi2: F64
    p_max: float
    deff: F64
    mean_ours: F64
    mean_ref: F64
    passed: bool

    @property
    def mean_z2(self) -> float:
        return float(self.chi2.sum() / max(int(self.blocks.sum()), 1))

    def summary(self) -> str:
        rel = self.mean_ours / np.where(self.mean_ref != 0, self.mean_ref, 1.0) - 1.0
        return (f"means ours {np.round(self.mean_ours, 5)} ref {np.round(self.mean_ref, 5)} "
                f"rel {np.round(rel, 4)}; block mean z² {self.mean_z2:.2f} "
                f"(χ² per channel {np.round(self.chi2, 1)} over {self.blocks.tolist()} blocks, "
                f"p {' '.join(f'{p:.2g}' for p in self.p_chi2)}), max |z| "
                f"{np.abs(self.z).max():.2f} (family p {self.p_max:.2g}), "
                f"deff {np.round(self.deff, 2)}")


#: Relative difference of noise-free pixels that is float32 accumulation, not a disagreement:
#: a render sums up to a few hundred float32 samples per pixel (256·2⁻²⁴ ≈ 1.5·10⁻⁵); Cycles'
#: sky seen directly reads 0.59999925 for 0.6.
FLOAT_RTOL = 2e-5


def _block_moments(runs: list, block: int) -> tuple[F64, F64, F64, F64, float]:
    """Block means (By, Bx, 3), their variance, its Satterthwaite degrees of freedom, and the
    between-seed variance of single-seed block means, from S ≥ 2 renders (h, w, ≥ 3)."""
    x = np.stack([np.asarray(r, np.float64)[..., :3] for r in runs])       # (S, h, w, 3)
    S, hh, ww, _ = x.shape
    x = x[:, :hh // block * block, :ww // block * block]
    by, bx, n = hh // block, ww // block, block * block

    def per_block(a):       # (..., h, w, 3) → (..., By, Bx, n, 3)
        a = a.reshape(*a.shape[:-3], by, block, bx, block, 3)
        return np.moveaxis(a, -4, -3).reshape(*a.shape[:-5], by, bx, n, 3)

    s2 = per_block(x.var(axis=0, ddof=1))                     # per-pixel sample variance
    mean = per_block(x.mean(axis=0)).mean(axis=-2)
    var = s2.sum(axis=-2) / (n * n * S)                      # variance of the block mean
    s2sum = s2.sum(axis=-2)
    dof = np.divide(s2sum ** 2, (s2 ** 2).sum(axis=-2) / (S - 1),
                    out=np.full(mean.shape, np.inf), where=s2sum > 0)
    between = per_block(x).mean(axis=-2).var(axis=0, ddof=1)  # (By, Bx, 3)
    return mean, var, dof, between, S


def compare_images(ours: list, ref: list, block: int = 8, significance: float = 1e-3) -> ImageComparison:
    """Do two renderers agree in expectation? Block means with z-scores from the renders' noise.

    Each list holds S ≥ 2 renders (h, w, ≥ 3) of the same scene with different seeds.
    Per block of ``block``×``block`` pixels and channel:

    1. the mean over seeds and pixels, and the variance of that mean from the per-pixel
       sample variances over the seeds (Σ s²/(n²S)) with Satterthwaite's degrees of freedom
       (a block whose variance comes from a few noisy pixels counts as a poor estimate);
    2. correlated noise (one VPL set lights many pixels in ERCUTS) makes the per-pixel
       formula too small: the seeds' own block means tell by how much. The inflation
       deff = Σ_blocks between-seed variance of a single seed's block mean / Σ S·var is
       pooled over all blocks and applied when it exceeds 1 (≈ 1 for pixel-independent
       estimators: PATH, BDPT, Cycles);
    3. Welch's t of the difference of the two renderers' block means, turned into the
       normal z with the same tail probability (Student's t with the combined
       Satterthwaite degrees of freedom).

    Blocks where both renderers are noise-free (a background, the sky in a perfect mirror)
    are left out when they agree to float32 accumulation (relative :data:`FLOAT_RTOL`) and
    count as infinitely far apart otherwise. The renderers agree when, for
    each channel, Σ z² over its blocks is within the χ²(blocks) tail and the largest |z|
    of all block channels within its Šidák-corrected normal tail, each at
    ``significance``/2 (the channel χ² tests Bonferroni-corrected over the three channels).
    Nothing else is tuned: the tolerance is the noise of the renders themselves.
    """
    from scipy.stats import chi2 as chi2_dist, norm, t as t_dist

    mo, vo, do, bo, so = _block_moments(ours, block)
    mr, vr, dr, br, sr = _block_moments(ref, block)
    deff = np.array([max(1.0, float(b.sum() / max(s * v.sum(), 1e-300)))
                     for b, v, s in ((bo, vo, so), (br, vr, sr))])
    vo, vr = vo * deff[0], vr * deff[1]
    diff, var = mo - mr, vo + vr
    with np.errstate(divide="ignore", invalid="ignore"):
        dof = var ** 2 / (np.where(np.isfinite(do), vo ** 2 / do, 0.0)
                          + np.where(np.isfinite(dr), vr ** 2 / dr, 0.0))
    noisy = var > 0
    z = np.zeros(diff.shape)
    t = np.divide(diff, np.sqrt(var), out=np.zeros(diff.shape), where=noisy)
    z[noisy] = np.sign(t[noisy]) * norm.isf(t_dist.sf(np.abs(t[noisy]), np.maximum(dof[noisy], 1.0)))
    off = ~noisy & (np.abs(diff) > FLOAT_RTOL * np.maximum(np.abs(mo), np.abs(mr)) + 1e-12)
    z[off] = np.inf
    counted = noisy | off
    blocks = counted.reshape(-1, 3).sum(axis=0)
    chi2 = (z ** 2).reshape(-1, 3).sum(axis=0)
    p_chi2 = np.array([chi2_dist.sf(c, k) if k > 0 else 1.0 for c, k in zip(chi2, blocks)])
    zmax = float(np.abs(z).max()) if counted.any() else 0.0
    m = max(int(blocks.sum()), 1)
    p_max = float(-np.expm1(m * np.log1p(-min(2.0 * norm.sf(zmax), 1.0)))) if np.isfinite(zmax) else 0.0
    passed = bool(p_chi2.min() >= significance / 6.0 and p_max >= significance / 2.0)
    mean_o = np.mean([np.asarray(r, np.float64)[..., :3].mean(axis=(0, 1)) for r in ours], axis=0)
    mean_r = np.mean([np.asarray(r, np.float64)[..., :3].mean(axis=(0, 1)) for r in ref], axis=0)
    return ImageComparison(z, chi2, blocks, p_chi2, p_max, deff, mean_o, mean_r, passed)
