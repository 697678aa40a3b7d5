"""The VPL clamp's bias compensation (Kollig & Keller 2004; :mod:`ercuts_core.integrators.ercuts.
bias_compensation`): its weight, its estimate of the removed light against a quadrature in a
corner, and the render's switch."""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
from numpy.typing import NDArray
from scipy.integrate import quad

from ercuts_core import RenderSettings, render
from ercuts_core.integrators.ercuts.bias_compensation import (COMPENSATION_MAX_RAYS, COMPENSATION_RAYS,
                                                               COMPENSATION_RR_DEPTH,
                                                               compensate, compensates, compensation_rays,
                                                               compensation_weight, reach)
from ercuts_core.integrators.ercuts.vpl import clamp_factor
from ercuts_core.integrators.path import next_event
from ercuts_core.description import MaterialTable
from ercuts_core.scene import BuiltScene
from ercuts_core.scenes import _Builder, _camera, _diffuse_table, closed_room
from ercuts_core.validate import sanitize

RHO = 0.5          # the corner's albedo
L0 = 2.0           # radiance the wall sends to the floor
GMAX = 4.0         # the clamp: cosθ/d² ≤ 4 m⁻², reach 0.5 m


@pytest.fixture(scope="module")
def corner():
    """A floor (y = 0, normal +y) meeting a wall (x = 0, normal +x), 4 m each way."""
    b = _Builder()
    o = b.object("Corner")
    b.quad((0, 0, -4), (0, 0, 4), (4, 0, 4), (4, 0, -4), 0, o)
    b.quad((0, 0, -4), (0, 4, -4), (0, 4, 4), (0, 0, 4), 0, o)
    desc = b.description(_diffuse_table([("Grey", [RHO] * 3)]), _camera((3, 2, 0), (0, 0, 0), 8, 6))
    return BuiltScene(sanitize(desc).desc, threads=1)


def test_weight_is_the_share_the_clamp_removes():
    d2 = np.array([0.01, 0.04, 0.25, 1.0, 0.04])
    cos = np.array([1.0, 0.5, 1.0, 1.0, 0.0])
    w = compensation_weight(GMAX, d2, cos)
    assert np.allclose(w, [0.96, 0.68, 0.0, 0.0, 0.0])
    assert np.allclose(w + clamp_factor(GMAX, d2, np.maximum(cos, 1e-300)), 1.0)
    assert (compensation_weight(np.inf, d2, cos) == 0).all()
    assert reach(GMAX) == 0.5 and reach(np.inf) == np.inf


def removed_light(s: float) -> float:
    """ΔL at a floor point s from the wall: (ρ/π)·L0·∫_wall cosθ_x cosθ_y/d² · w dA, in polar
    coordinates r around the wall's foot point (∫ sinφ dφ over the half-disc = 2):
    ∫ 2 r² s/(s² + r²)² · max(0, 1 − g·(s² + r²)^{3/2}/s) dr."""
    r_max = np.sqrt((s / GMAX) ** (2 / 3) - s * s)

    def f(r):
        d2 = s * s + r * r
        return 2 * r * r * s / d2 ** 2 * max(0.0, 1.0 - GMAX * d2 ** 1.5 / s)
    return RHO / np.pi * L0 * quad(f, 0.0, r_max, epsabs=1e-12, limit=200)[0]


@pytest.mark.parametrize("s", [0.03, 0.1, 0.2])
def test_compensation_estimates_the_removed_light(corner, s):
    """One level (the wall's L_o given): the mean over 200 000 receivers at distance s from the
    wall agrees with the quadrature within 4 standard errors of the mean, and the error is
    small enough (< 3 %) for the check to mean something."""
    n = 200_000
    p = np.tile([s, 0.0, 0.0], (n, 1))
    up = np.tile([0.0, 1.0, 0.0], (n, 1))

    def radiance_at(q, ng, ns, wo, mat):          # the wall shines L0, the floor nothing
        return np.where((q[:, 0] < 1e-6)[:, None], L0, 0.0) * np.ones((len(q), 3))

    out, near = compensate(corner, GMAX, p, up, up, up, np.zeros(n, np.int64), np.random.default_rng(5),
                           radiance_at, depth=1)
    y = out[:, 1]
    mean, se = y.mean(), y.std(ddof=1) / np.sqrt(n)
    true = removed_light(s)
    assert se < 0.03 * true
    assert abs(mean - true) < 4 * se, (mean, true, se)
    assert np.array_equal(near, out[:, 0] > 0)


def test_no_compensation_from_surfaces_that_hold_no_vpl():
    """Mirrors, glass and polished metals hold no VPL (``Bsdf.is_specular_or_glass``): the
    clamp took no light from them, and the paths that reflect there are the direct passes'.
    A compensation ray that lands on one adds nothing (it added that light a second time).
    The corner's wall is a polished metal here: every receiver's compensation is 0, while
    the grey wall's is not (:func:`test_compensation_estimates_the_removed_light`)."""
    b = _Builder()
    o = b.object("Corner")
    b.quad((0, 0, -4), (0, 0, 4), (4, 0, 4), (4, 0, -4), 0, o)
    b.quad((0, 0, -4), (0, 4, -4), (0, 4, 4), (0, 0, 4), 1, o)
    mats = MaterialTable(["Grey", "Metal"], [[RHO] * 3, [0.9] * 3], [1.0, 0.3], [0.0, 1.0], [0.0, 0.5],
                         np.zeros((2, 3)), (), [0.0, 0.0], [1.5, 1.5])
    scene = BuiltScene(sanitize(b.description(mats, _camera((3, 2, 0), (0, 0, 0), 8, 6))).desc, threads=1)
    assert scene.has_specular_or_glass
    n = 20_000
    p = np.tile([0.1, 0.0, 0.0], (n, 1))
    up = np.tile([0.0, 1.0, 0.0], (n, 1))
    out, near = compensate(scene, GMAX, p, up, up, up, np.zeros(n, np.int64), np.random.default_rng(5),
                           lambda q, *a: np.full((len(q), 3), L0), depth=1)
    assert not out.any() and not near.any()


PLATE_RHO = 0.8     # the plates' albedo
GAP = 0.1           # the plates' distance [m]; with g_max = 1 m⁻² (reach 1 m), a = g·GAP² = 0.01


def plates(emitting_floor: bool) -> BuiltScene:
    """A grey floor (y = 0, normal +y) under a grey ceiling (y = GAP, normal −y), 20 m × 20 m:
    light that the clamp removes bounces between them many times. With ``emitting_floor`` the
    floor emits radiance 1 (two-sided) and lights the ceiling from 0.1 m away."""
    b = _Builder()
    o = b.object("Plates")
    b.quad((-10, 0, 10), (10, 0, 10), (10, 0, -10), (-10, 0, -10), 0, o)
    b.quad((-10, GAP, -10), (10, GAP, -10), (10, GAP, 10), (-10, GAP, 10), 1, o)
    table = _diffuse_table([("Floor", [PLATE_RHO] * 3, [1.0 * emitting_floor] * 3), ("Ceiling", [PLATE_RHO] * 3)])
    return BuiltScene(sanitize(b.description(table, _camera((0, 0.05, 5), (0, 0.05, 0), 8, 6))).desc, threads=1)


def plate_share() -> float:
    """W = E[w] over one cosine-sampled direction from a plate to the other, u = cosθ:
    w = max(0, 1 − a/u³) (d = GAP/u, cosθ_y = u), so W = ∫_{u0}^1 (1 − a/u³)·2u du
    = 1 − u0² − 2a(1/u0 − 1), u0 = a^{1/3}."""
    a = 1.0 * GAP ** 2
    u0 = a ** (1 / 3)
    return 1 - u0 * u0 - 2 * a * (1 / u0 - 1)


def _mean_and_error(out: NDArray) -> tuple[float, float]:
    y = out[:, 1]
    return float(y.mean()), float(y.std(ddof=1) / np.sqrt(len(y)))


def _floor_receivers(n: int):
    p = np.tile([0.0, 0.0, 0.0], (n, 1))
    up = np.tile([0.0, 1.0, 0.0], (n, 1))
    return p, up, up, up, np.zeros(n, np.int64)


def test_the_recursion_follows_the_light_between_close_plates():
    """Every surface shines L0 (its clamped light, given): level k adds (ρW)^k·L0, so the
    removed light is L0·ρW/(1 − ρW) (ρW = 0.70: 2.39·L0). Russian roulette after
    :data:`COMPENSATION_RR_DEPTH` levels keeps every level; the recursion stopped after three
    (stop 44's rule) gives L0·Σ_{k≤3}(ρW)^k = 1.55·L0 — in the Cornell box's 1 cm gap above
    its lamp that rule returned 4.3 of the clamp's 6.1 (24 seeds, 64×48), now 5.95."""
    scene, n = plates(False), 100_000
    rw = PLATE_RHO * plate_share()

    def run(**kw):
        out, _ = compensate(scene, 1.0, *_floor_receivers(n), np.random.default_rng(7),
                            lambda q, *a: np.full((len(q), 3), L0), **kw)
        return _mean_and_error(out)
    mean, se = run()
    true = L0 * rw / (1 - rw)
    assert se < 0.02 * true
    assert abs(mean - true) < 4 * se, (mean, true, se)
    cut, se3 = run(depth=3, rr_depth=4)
    assert abs(cut - L0 * (rw + rw ** 2 + rw ** 3)) < 4 * se3, cut


def test_the_bsdf_samples_find_the_emission_that_light_sampling_misses():
    """The floor emits and lights the ceiling 0.1 m above it: the ceiling's direct light is
    ρ·Le, almost all of it from the floor right below, where a light sample over the 400 m²
    emitter rarely lands (power heuristic weight ≈ 0). ``radiance_at`` takes next-event
    estimation with MIS, and the compensation's BSDF samples collect the other half
    (``emission_mis``): the removed light is ρLe·Σ_{k odd}(ρW)^k = ρLe·ρW/(1 − (ρW)²) (the
    floor has no direct light of its own). Without the BSDF half nearly all of it is lost."""
    scene, n = plates(True), 100_000
    rw = PLATE_RHO * plate_share()
    nee_rng = np.random.default_rng(11)

    def radiance_at(q, ng, ns, wo, mat):
        bsdf = scene.bsdf(mat, ns, ng, q)
        return next_event(scene, SimpleNamespace(p=q, ns=ns, ng=ng), wo, bsdf, nee_rng)

    def run(emission_mis):
        out, _ = compensate(scene, 1.0, *_floor_receivers(n), np.random.default_rng(7), radiance_at,
                            emission_mis=emission_mis)
        return _mean_and_error(out)
    mean, se = run(True)
    true = PLATE_RHO * 1.0 * rw / (1 - rw * rw)
    assert se < 0.02 * true
    assert abs(mean - true) < 4 * se, (mean, true, se)
    assert run(False)[0] < 0.2 * true


def test_no_clamp_no_compensation(corner):
    p = np.array([[0.1, 0.0, 0.0]])
    up = np.array([[0.0, 1.0, 0.0]])
    out, near = compensate(corner, np.inf, p, up, up, up, np.zeros(1, np.int64), np.random.default_rng(0),
                           lambda *a: np.ones((len(a[0]), 3)))
    assert not out.any() and not near.any()


def test_the_switch():
    s = RenderSettings()
    assert s.clamp_compensation and compensates(s, 4.0)
    assert not compensates(s, np.inf)                                       # clamp 0
    assert not compensates(RenderSettings(clamp_compensation=False), 4.0)
    assert not compensates(RenderSettings(direct_light="VPL"), 4.0)


@pytest.fixture(scope="module")
def room_renders():
    """The closed room, compensated and not, same seed (small and fast)."""
    scene = closed_room(32, 24)
    base = dict(integrator="ERCUTS", rough_samples=4, chain_length=20, e1_samples=32, seed=3, threads=1)
    return {c: render(scene, RenderSettings(clamp_compensation=c, **base)) for c in (True, False)}


def test_render_reports_the_compensation(room_renders):
    """The compensated render reports the compensation (points reached, energy added), and the
    ablation does not run it."""
    on, off = room_renders[True].stats, room_renders[False].stats
    assert 0 < on["compensated_points"] < 1 and on["compensated_energy"] > 0
    assert on["compensation_rays"] == compensation_rays(32 * 24) == 16     # a small film: the most
    assert "compensated_points" not in off and "compensated_energy" not in off
    assert np.isfinite(room_renders[True].image).all()


def test_rays_per_point_follow_the_film_size():
    """Small films average several compensation rays per point, production sizes send one."""
    assert compensation_rays(160 * 120) == COMPENSATION_RAYS // (160 * 120) == 13
    assert compensation_rays(640 * 480) == compensation_rays(1920 * 1080) == 1
    assert compensation_rays(0) == compensation_rays(10) == COMPENSATION_MAX_RAYS
