"""Tests of ercuts_core.sampling: warps, frames, Distribution1D and MIS heuristics.

Follows pbrt-v4 ``util/sampling_test.cpp`` (inverse-warp round trips on a stratified grid,
|Δu| < 1e-3; discrete-sampler pmf consistency) and Mitsuba 3 ``chi2.py`` (chi² of every
warp against its pdf, Šidák-corrected over the chi² tests of this file). Every statistical
test uses a fixed seed; the harness itself is shown to reject wrong pdfs.
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
try:
    from tests.stats import (PlanarDomain, SphericalDomain, chi2_from_tables, chi2_test,
                             integrate_pdf, z_test_mean)
except ImportError:  # tests/ is not a package: pytest put tests/ itself on sys.path
    from stats import (PlanarDomain, SphericalDomain, chi2_from_tables, chi2_test,
                       integrate_pdf, z_test_mean)

from ercuts_core import sampling as S

N_CHI2 = 300_000


# ---------------------------------------------------------------------------------------
# Warp table: (sample(u), pdf(points), invert(points) or None, chi² domain)
# ---------------------------------------------------------------------------------------

def _disk_pdf(p):
    return np.where(np.sum(p * p, axis=1) <= 1.0, 1.0 / np.pi, 0.0)


def _triangle_pdf(b01):
    """Density of (b0, b1) for a uniform triangle: 2 on the simplex b0, b1 >= 0, b0 + b1 <= 1."""
    inside = (b01[:, 0] >= 0) & (b01[:, 1] >= 0) & (b01.sum(axis=1) <= 1.0)
    return np.where(inside, 2.0, 0.0)


def _cone_pdf(cos_max):
    return lambda w: np.where(w[:, 2] >= cos_max, S.uniform_cone_pdf(cos_max), 0.0)


WARPS = {
    "cosine_hemisphere": (S.sample_cosine_hemisphere,
                          lambda w: S.cosine_hemisphere_pdf(w[:, 2]),
                          S.invert_cosine_hemisphere_sample, SphericalDomain()),
    "uniform_sphere": (S.sample_uniform_sphere,
                       lambda w: np.full(w.shape[0], S.uniform_sphere_pdf()),
                       S.invert_uniform_sphere_sample, SphericalDomain()),
    "uniform_cone_0.7": (lambda u: S.sample_uniform_cone(u, 0.7), _cone_pdf(0.7),
                         lambda w: S.invert_uniform_cone_sample(w, 0.7), SphericalDomain()),
    # A narrow cone: zoom 2 spreads it over several rows of the grid
    "uniform_cone_0.99": (lambda u: S.sample_uniform_cone(u, 0.99), _cone_pdf(0.99),
                          lambda w: S.invert_uniform_cone_sample(w, 0.99),
                          SphericalDomain(zoom=2.0)),
    "disk_concentric": (S.sample_uniform_disk_concentric, _disk_pdf,
                        S.invert_uniform_disk_concentric,
                        PlanarDomain(((-1.0, 1.0), (-1.0, 1.0)))),
    "triangle": (lambda u: S.sample_uniform_triangle(u)[:, :2], _triangle_pdf,
                 lambda b: S.invert_uniform_triangle(np.column_stack([b, 1 - b.sum(axis=1)])),
                 PlanarDomain()),
}


def _res(domain):
    """Odd grid resolutions (Mitsuba): sphere 51 × 101 cells, plane 31 × 31."""
    return (51, 101) if isinstance(domain, SphericalDomain) else (31, 31)


@pytest.mark.parametrize("name", list(WARPS))
def test_warp_chi2(name):
    sample, pdf, _, domain = WARPS[name]
    rt, rp = _res(domain)
    ok, msg = chi2_test(sample, pdf, n_samples=N_CHI2, res_theta=rt, res_phi=rp,
                        test_count=len(WARPS), seed=1, domain=domain)
    assert ok, f"{name}: {msg}"


@pytest.mark.parametrize("name", list(WARPS))
def test_warp_pdf_integrates_to_one(name):
    # Adaptive cell quadrature; the 1e-3 slack covers the indicator-function boundaries
    # (disk, triangle, cone) that the adaptive rule resolves to ~1e-4.
    _, pdf, _, domain = WARPS[name]
    assert integrate_pdf(pdf, domain, res=_res(domain)) == pytest.approx(1.0, abs=1e-3)


@pytest.mark.parametrize("name", list(WARPS))
def test_warp_inverse_round_trip(name):
    # 32 × 32 stratum centres (pbrt: 1000 stratified points), |Δu| < 1e-3
    sample, _, invert, _ = WARPS[name]
    g = (np.arange(32) + 0.5) / 32
    u = np.stack(np.meshgrid(g, g, indexing="ij"), axis=-1).reshape(-1, 2)
    u_back = invert(sample(u))
    assert np.max(np.abs(u_back - u)) < 1e-3


def test_warps_at_the_sample_domain_corners_are_finite():
    u = np.array([[0.0, 0.0], [0.0, S.ONE_MINUS_EPSILON], [S.ONE_MINUS_EPSILON, 0.0],
                  [S.ONE_MINUS_EPSILON, S.ONE_MINUS_EPSILON], [0.5, 0.5]])
    with np.errstate(all="raise"):
        for sample, _, invert, _ in WARPS.values():
            out = sample(u)
            assert np.all(np.isfinite(out)) and np.all(np.isfinite(invert(out)))
        assert np.allclose(np.linalg.norm(S.sample_cosine_hemisphere(u), axis=1), 1.0)
        assert np.allclose(np.linalg.norm(S.sample_uniform_sphere(u), axis=1), 1.0)


def test_triangle_barycentrics_are_valid():
    b = S.sample_uniform_triangle(np.random.default_rng(2).random((10_000, 2)))
    assert np.all(b >= -1e-15) and np.allclose(b.sum(axis=1), 1.0)


def test_cone_pdf_degenerate_cone_is_a_delta():
    with np.errstate(all="raise"):
        pdf = S.uniform_cone_pdf(np.array([1.0, 0.5, -1.0]))
    assert np.isinf(pdf[0])
    assert pdf[1:] == pytest.approx([1 / np.pi, 1 / (4 * np.pi)])


def test_luminance():
    assert S.luminance([1.0, 1.0, 1.0]) == pytest.approx(1.0)
    assert S.luminance(np.eye(3)) == pytest.approx([0.2126, 0.7152, 0.0722])


# ---------------------------------------------------------------------------------------
# The chi² harness must be able to fail
# ---------------------------------------------------------------------------------------

def _cos_power_hemisphere(power):
    """Sampler of the normalized lobe (p+1)/(2π) cos^p θ (cosθ = u^(1/(p+1)))."""
    def sample(u):
        cos_t = u[:, 0] ** (1.0 / (power + 1.0))
        sin_t = np.sqrt(1.0 - cos_t ** 2)
        phi = 2 * np.pi * u[:, 1]
        return np.stack([sin_t * np.cos(phi), sin_t * np.sin(phi), cos_t], axis=1)
    return sample


@pytest.mark.parametrize("case", ["cos2_vs_cos", "cos1.2_vs_cos", "pdf_times_1.1",
                                  "sphere_vs_hemisphere", "polar_disk"])
def test_chi2_rejects_wrong_pdf(case):
    cos_pdf = lambda w: S.cosine_hemisphere_pdf(w[:, 2])  # noqa: E731
    domain = None
    if case == "cos2_vs_cos":        # cos² sampling tested against the cos pdf
        sample, pdf = _cos_power_hemisphere(2.0), cos_pdf
    elif case == "cos1.2_vs_cos":    # a subtle shape error, both normalized
        sample, pdf = _cos_power_hemisphere(1.2), cos_pdf
    elif case == "pdf_times_1.1":    # right shape, wrong normalization (integral 1.1)
        sample, pdf = S.sample_cosine_hemisphere, lambda w: 1.1 * cos_pdf(w)
    elif case == "sphere_vs_hemisphere":  # samples where the pdf is zero
        sample, pdf = S.sample_uniform_sphere, lambda w: np.where(w[:, 2] > 0, 0.5 / np.pi, 0.0)
    else:                            # r = u₀ polar map is not area preserving
        def sample(u):
            return np.stack([u[:, 0] * np.cos(2 * np.pi * u[:, 1]),
                             u[:, 0] * np.sin(2 * np.pi * u[:, 1])], axis=1)
        pdf, domain = _disk_pdf, PlanarDomain(((-1.0, 1.0), (-1.0, 1.0)))
    ok, msg = chi2_test(sample, pdf, n_samples=N_CHI2, seed=3, domain=domain)
    assert not ok, msg


def test_chi2_from_tables_pools_small_cells():
    expected = np.array([1.0, 1.0, 2.0, 50.0, 50.0, 100.0])
    ok, msg, p = chi2_from_tables(expected.copy(), expected, n_samples=204)
    assert ok and p == pytest.approx(1.0), msg
    ok, msg, _ = chi2_from_tables(np.array([0.0, 0, 0, 80, 20, 104]), expected, n_samples=204)
    assert not ok, msg


def test_z_test_mean():
    rng = np.random.default_rng(4)
    x = rng.normal(1.0, 2.0, size=100_000)
    assert z_test_mean(x, 1.0) > 0.01
    assert z_test_mean(x, 1.05) < 1e-6  # 0.05 is 7.9 standard errors (2/√1e5 = 0.0063)
    assert z_test_mean(np.ones(10), 1.0) == 1.0 and z_test_mean(np.ones(10), 1.1) == 0.0


# ---------------------------------------------------------------------------------------
# Frames
# ---------------------------------------------------------------------------------------

def _special_normals():
    """The poles, the axes, and normals within 1e-9 (and 1e-300) of (0, 0, −1)."""
    tiny = 1e-9
    n = np.array([[0, 0, 1], [0, 0, -1], [1, 0, 0], [0, 1, 0], [-1, 0, 0],
                  [tiny, 0, -1], [0, tiny, -1], [tiny, -tiny, -1], [-tiny, tiny, 1],
                  [1e-300, 0, -1], [0.6, 0.0, -0.8], [0.0, 0.8, -0.6]], dtype=np.float64)
    n = n / np.linalg.norm(n, axis=1, keepdims=True)
    # z = −0.0 (copysign picks the lower chart)
    return np.vstack([n, [[1.0, 0.0, -0.0]], [[0.0, -1.0, -0.0]]])


def _assert_frame(n, t, b, atol=1e-12):
    dot = lambda a, c: np.einsum("ij,ij->i", a, c)  # noqa: E731
    assert np.allclose(dot(t, t), 1, atol=atol) and np.allclose(dot(b, b), 1, atol=atol)
    assert np.allclose(dot(t, b), 0, atol=atol)
    assert np.allclose(dot(t, n), 0, atol=atol) and np.allclose(dot(b, n), 0, atol=atol)
    assert np.allclose(np.cross(t, b), n, atol=atol)  # right-handed


def test_coordinate_system_special_normals():
    n = _special_normals()
    with np.errstate(all="raise"):
        t, b = S.coordinate_system(n)
    _assert_frame(n, t, b)


def test_coordinate_system_random_and_round_trip():
    rng = np.random.default_rng(5)
    n = S.sample_uniform_sphere(rng.random((10_000, 2)))
    t, b = S.coordinate_system(n)
    _assert_frame(n, t, b)
    v = rng.normal(size=(10_000, 3))
    local = S.to_local(v, t, b, n)
    assert np.allclose(local[:, 2], np.einsum("ij,ij->i", v, n))
    assert np.allclose(S.to_world(local, t, b, n), v, atol=1e-12)


@settings(max_examples=200, deadline=None)
@given(st.tuples(*[st.floats(-1.0, 1.0, allow_subnormal=False)] * 3).filter(
    lambda v: 1e-6 < np.linalg.norm(v)))
def test_coordinate_system_property(v):
    n = np.asarray(v, np.float64)[None, :]
    n = n / np.linalg.norm(n)
    t, b = S.coordinate_system(n)
    _assert_frame(n, t, b, atol=1e-10)


# ---------------------------------------------------------------------------------------
# Distribution1D
# ---------------------------------------------------------------------------------------

WEIGHTS = np.array([0.0, 1.0, 3.0, 0.0, 0.5, 2.0, 0.0, 1e-3, 0.0])


def test_distribution1d_tables():
    d = S.Distribution1D(WEIGHTS)
    assert d.total == pytest.approx(WEIGHTS.sum())
    assert d.pmf.shape == (9,) and d.cdf.shape == (10,)
    assert d.cdf[0] == 0.0 and d.cdf[-1] == 1.0 and np.all(np.diff(d.cdf) >= 0)
    assert np.allclose(d.pmf, WEIGHTS / WEIGHTS.sum())


def test_distribution1d_chi2_and_pmf_consistency():
    d = S.Distribution1D(WEIGHTS)
    n = 200_000
    idx, pmf = d.sample(np.random.default_rng(6).random(n))
    assert idx.dtype == np.int64
    # pmf returned by sample() == pmf_of(idx) == w/Σw (pbrt BVHLightSampling.PdfMethod)
    assert np.array_equal(pmf, d.pmf_of(idx)) and np.allclose(pmf, WEIGHTS[idx] / d.total)
    assert np.all(WEIGHTS[idx] > 0)  # zero weights are never sampled
    counts = np.bincount(idx, minlength=WEIGHTS.size)
    ok, msg, _ = chi2_from_tables(counts, d.pmf * n, n)
    assert ok, msg


def test_distribution1d_edges():
    d = S.Distribution1D(WEIGHTS)
    idx, pmf = d.sample(np.array([0.0, S.ONE_MINUS_EPSILON, 1.0, d.cdf[2], d.cdf[4]]))
    assert np.all(pmf > 0) and np.all(WEIGHTS[idx] > 0)
    assert idx[0] == 1 and idx[1] == 7 and idx[2] == 7 and idx[3] == 2
    assert np.array_equal(d.pmf_of([-1, 9, 3]), [0.0, 0.0, 0.0])


def test_distribution1d_zero_total_and_invalid():
    for w in (np.zeros(4), np.zeros(0)):
        d = S.Distribution1D(w)
        idx, pmf = d.sample(np.array([0.3, 0.9]))
        assert d.total == 0.0 and np.all(idx == 0) and np.all(pmf == 0.0)
    for bad in ([1.0, -1.0], [np.nan, 1.0], [np.inf, 1.0]):
        with pytest.raises(ValueError):
            S.Distribution1D(bad)


# ---------------------------------------------------------------------------------------
# MIS heuristics
# ---------------------------------------------------------------------------------------

def test_heuristics_special_values():
    heuristic = S.power_heuristic
    inf = np.inf
    pf = np.array([0.0, 0.0, 1.0, inf, inf, 1.0, 1e200, 1e-200, 1e-320])
    pg = np.array([0.0, 1.0, 0.0, 1.0, inf, inf, 1e200, 3e-200, 0.0])
    with np.errstate(all="raise"):
        w = heuristic(pf, pg)
        w_rev = heuristic(pg, pf)
    assert np.all(np.isfinite(w))
    assert list(w[:6]) == [0.0, 0.0, 1.0, 1.0, 0.5, 0.0]
    assert w[6] == pytest.approx(0.5) and w[8] == 1.0
    # The weights of two strategies sum to 1 wherever at least one pdf is non-zero
    assert np.allclose((w + w_rev)[1:], 1.0)


def test_heuristics_values():
    rng = np.random.default_rng(7)
    pf, pg = rng.random(100) * 10, rng.random(100) * 10
    assert np.allclose(S.power_heuristic(2 * pf, 3 * pg),
                       (2 * pf) ** 2 / ((2 * pf) ** 2 + (3 * pg) ** 2))
