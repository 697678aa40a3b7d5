"""Soft lights as Cycles renders them: point/spot lights with a radius (sphere and soft-falloff
disk), suns with an angle, area lights with a spread.

* Sampling: chi² of every next-event sampler against an analytic density written here
  independently of the implementation, and the returned ``pdf_w`` equal to it.
* Power: the light a surface receives is the same whether it is computed with next-event
  estimation (``illuminate``) or with light tracing (``emit`` + ``emission_reaches``), and
  equals the analytic value where there is one (a sphere light's 4πI; a disk light's
  distance-dependent flux through a sphere; a spread light's π·L·A).
* Transport: BDPT (every strategy, MIS with the emission densities) agrees with PATH
  (next-event estimation only) pixel by pixel; ERCUTS's image energy agrees with BDPT's.
* Radius 0 / angle 0 / spread π keep the delta and plain lights' exact samples.
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))
from stats import PlanarDomain, SphericalDomain, chi2_test, frame_from_pole, z_test_mean  # noqa: E402
from test_bdpt import _assert_agree, _renders  # noqa: E402

from ercuts_core import AreaLights, MaterialTable, MeshTable, PointLights, SunLights  # noqa: E402
from ercuts_core.description import SHAPE_ELLIPSE, SHAPE_RECT, SceneDescription  # noqa: E402
from ercuts_core.sampling import luminance  # noqa: E402
from ercuts_core.scene import BuiltScene  # noqa: E402
from ercuts_core.scenes import _camera, cornell_box, point_lit_box  # noqa: E402
from ercuts_core.validate import sanitize  # noqa: E402

N_CHI2 = 300_000
#: chi² tests in this file (Šidák correction of the 1 % family level).
CHI2_TESTS = 9
C = np.array([0.25, 1.5, -0.125])                    # light centre (exact in float32)


def lightset(points=None, suns=None, areas=None):
    """The LightSet of a scene made of a floor and the given lights."""
    pos = np.array([[-4, 0, -4], [4, 0, -4], [4, 0, 4], [-4, 0, 4]])
    mats = MaterialTable.diffuse(["Grey"], [[0.5, 0.5, 0.5]])
    kw = {k: v for k, v in (("point_lights", points), ("sun_lights", suns), ("area_lights", areas))
          if v is not None}
    d = SceneDescription(MeshTable(pos, [[0, 2, 1], [0, 3, 2]], [0, 0], [0, 0]), mats,
                         _camera((0, 1, 3), (0, 0, 0), 8, 6), object_names=("Floor", "L"), **kw)
    return BuiltScene(sanitize(d).desc).lights


def soft_point(radius, sphere, spot_deg=None, blend=0.0, intensity=(2.0, 2.0, 2.0)):
    cos = np.cos(np.radians(spot_deg) / 2) if spot_deg is not None else -1.0
    return PointLights([C], [intensity], [[0.3, -1, 0.1]], [cos], [blend], [radius], [1], [sphere])


# --------------------------------------------------------------------------- analytic densities
def _f32(v):
    """The value as the description stores it (float32)."""
    return float(np.float32(v))


def sphere_pdf(x, r):
    """Uniform density over the cone of directions from x to the sphere (C, r)."""
    r = _f32(r)

    def pdf(w):
        v = C - x
        d = np.linalg.norm(v)
        cos_a = np.sqrt(1 - (r / d) ** 2)
        return np.where(w @ (v / d) >= cos_a, 1 / (2 * np.pi * (1 - cos_a)), 0.0)
    return pdf


def facing_disk_pdf(x, r):
    """Solid-angle density of uniform area samples of the disk (C, r) facing x."""
    r = _f32(r)

    def pdf(w):
        n = (x - C) / np.linalg.norm(x - C)
        cw = -(w @ n)
        t = np.linalg.norm(x - C) / np.where(cw > 0, cw, 1.0)
        hit = x + w * t[:, None]
        inside = (cw > 0) & (np.linalg.norm(hit - C, axis=1) <= r)
        return np.where(inside, t * t / (np.pi * r * r * np.maximum(cw, 1e-300)), 0.0)
    return pdf


def cone_pdf(axis, half):
    def pdf(w):
        return np.where(w @ axis >= np.cos(half), 1 / (2 * np.pi * (1 - np.cos(half))), 0.0)
    return pdf


def _chi2_directions(ls, x, pdf, pole, zoom):
    def sample(u):
        n = len(u)
        s = ls.illuminate(np.broadcast_to(x, (n, 3)).copy(), np.full(n, 0.5), u)
        np.testing.assert_allclose(s.pdf_w[s.valid], pdf(s.wi[s.valid]), rtol=1e-7)
        return s.wi, s.valid
    ok, msg = chi2_test(sample, pdf, n_samples=N_CHI2, test_count=CHI2_TESTS,
                        domain=SphericalDomain(frame_from_pole(pole), zoom=zoom))
    assert ok, msg


@pytest.mark.parametrize("r, x", [(0.3, (0.6, 0.2, 0.5)), (0.05, (-1.0, 0.0, 1.5))])
def test_sphere_light_samples_its_visible_cap_uniformly(r, x):
    x = np.array(x, float)
    _chi2_directions(lightset(points=soft_point(r, True)), x, sphere_pdf(x, r), C - x, zoom=3.0)


@pytest.mark.parametrize("r, x", [(0.3, (0.6, 0.2, 0.5)), (0.6, (0.4, 1.3, 0.2))])
def test_soft_falloff_light_samples_the_disk_facing_the_receiver(r, x):
    """The second receiver is 0.36 m from the centre, closer than the radius."""
    x = np.array(x, float)
    _chi2_directions(lightset(points=soft_point(r, False)), x, facing_disk_pdf(x, r), C - x, zoom=2.0)


def test_sphere_light_from_inside_sees_radiance_everywhere():
    ls = lightset(points=soft_point(0.5, True, spot_deg=40))
    x = np.broadcast_to(C + [0.1, -0.2, 0.05], (4000, 3)).copy()
    s = ls.illuminate(x, np.full(len(x), 0.5), np.random.default_rng(1).random((len(x), 2)))
    assert s.valid.all()
    np.testing.assert_allclose(s.Li, 2.0 / (np.pi * 0.25))     # L = I/(πr²), no spot factor
    np.testing.assert_allclose(s.pdf_w, 1 / (4 * np.pi))
    np.testing.assert_allclose(np.linalg.norm(s.p - C, axis=1), 0.5)
    assert (s.pdf_dir == 0).all()                                # light tracing cannot reach it


@pytest.mark.parametrize("sphere", [True, False])
def test_lights_a_ray_crosses_add_up_as_cycles_lights_are_transparent(sphere):
    """A ray after a mirror (:meth:`LightSet.radiance_along`) that crosses two soft lights sees
    the sum of their radiances, as Cycles renders it (its path continues past a light it hit);
    the nearer light's alone made the glossy sweep's mirror 2–4 % too dark where the two
    largest lights overlap. A surface before the lights (``t_max``) hides both."""
    small, big = np.array([0.0, 1.0, 0.0]), np.array([0.0, 1.0, -1.0])
    I = np.array([[2.0, 1.0, 0.5], [0.5, 1.0, 3.0]])
    ls = lightset(points=PointLights([small, big], I, [[0, -1, 0]] * 2, [-1, -1], [0, 0], [0.2, 0.4],
                                     [1, 1], [sphere, sphere]))
    o = np.array([[0.0, 1.0, 3.0]] * 4)
    d = np.array([[0.0, 0.0, -1.0], [0.0, 0.0, -1.0], [0.3, 0.0, -4.0], [0.0, 0.0, -1.0]])
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    t_max = np.array([np.inf, 10.0, np.inf, 2.0])       # the last ray meets a surface first
    L = I / (np.pi * np.array([[0.2 ** 2], [0.4 ** 2]]))
    expect = np.array([L[0] + L[1], L[0] + L[1], L[1], [0.0, 0.0, 0.0]])
    np.testing.assert_allclose(ls.radiance_along(o, d, t_max), expect, rtol=1e-5)


def test_sun_angle_samples_its_cone_uniformly():
    half = np.radians(6.0)
    d = np.array([0.3, -1.0, 0.2]) / np.linalg.norm([0.3, -1.0, 0.2])
    ls = lightset(suns=SunLights([d], [[3, 3, 3]], [2 * half], [1]))
    _chi2_directions(ls, np.zeros(3), cone_pdf(-d, half), -d, zoom=3.0)


def _spread_light(spread, shape=SHAPE_RECT):
    """A 1.6 m × 1.0 m light 1.2 m above the floor, facing down and slightly tilted."""
    n = np.array([0.15, -1.0, 0.05])
    n /= np.linalg.norm(n)
    u = np.cross(n, [0, 0, 1.0])
    u /= np.linalg.norm(u)
    v = np.cross(n, u)
    return AreaLights([[0.1, 1.2, 0.0]], [u * 0.8], [v * 0.5], [n], [[1.0, 2.0, 3.0]], [shape], [1],
                      [spread])


@pytest.mark.parametrize("shape", [SHAPE_RECT, SHAPE_ELLIPSE])
def test_spread_light_samples_the_reachable_part_uniformly(shape):
    """Samples are uniform in the part of the light's (α, β) box that can reach the receiver
    (the box of the spread circle); the returned densities say so."""
    al = _spread_light(np.radians(40), shape)
    ls = lightset(areas=al)
    x = np.array([0.3, 0.0, 0.2])
    c, au, av = (a.astype(np.float64)[0] for a in (al.center, al.axis_u, al.axis_v))
    nrm = al.normal.astype(np.float64)[0]
    t = (x - c) @ nrm
    radius = t * np.tan(_f32(np.radians(40)) / 2)
    ab_c = np.array([(x - c) @ au / (au @ au), (x - c) @ av / (av @ av)])
    half_w = radius / np.array([np.linalg.norm(au), np.linalg.norm(av)])
    lo, hi = np.maximum(ab_c - half_w, -1), np.minimum(ab_c + half_w, 1)
    jac = np.linalg.norm(np.cross(au, av))

    def sample(uu):
        n = len(uu)
        s = ls.illuminate(np.broadcast_to(x, (n, 3)).copy(), np.full(n, 0.5), uu)
        ab = np.stack([(s.p - c) @ au / (au @ au), (s.p - c) @ av / (av @ av)], axis=1)
        cos_l = -(s.wi @ nrm)
        area_pdf = s.pdf_w * cos_l / s.dist**2
        np.testing.assert_allclose(area_pdf, 1 / (np.prod(hi - lo) * jac), rtol=1e-9)
        back = ls.pdf_illuminate_vertex(s.light, np.broadcast_to(x, (n, 3)), s.p)
        np.testing.assert_allclose(back, area_pdf, rtol=1e-9)
        return ab, np.ones(n, bool)

    def pdf(ab):
        inside = ((ab >= lo) & (ab <= hi)).all(axis=1)
        return np.where(inside, 1 / np.prod(hi - lo), 0.0)

    ok, msg = chi2_test(sample, pdf, n_samples=N_CHI2, res_theta=31, res_phi=31, test_count=CHI2_TESTS,
                        domain=PlanarDomain(((-1, 1), (-1, 1))))
    assert ok, msg


# --------------------------------------------------------------------------- power
def _nee_flux_through_sphere(ls, R, n=400_000, seed=3):
    """Φ = ∮ E dA over the sphere of radius R about C (receivers facing the centre)."""
    rng = np.random.default_rng(seed)
    w = rng.normal(size=(n, 3))
    w /= np.linalg.norm(w, axis=1, keepdims=True)
    x = C + R * w
    s = ls.illuminate(x, rng.random(n), rng.random((n, 2)))
    e = luminance(s.Li) * np.maximum(-(s.wi * w).sum(1), 0) / np.where(s.valid, s.pdf_w, 1) * s.valid
    return 4 * np.pi * R * R * e


def _emit_flux_through_sphere(ls, R, n=400_000, seed=4):
    """Φ by light tracing: every emitted line's throughput where it meets the sphere R about C,
    if it lights that receiver (emission_reaches)."""
    rng = np.random.default_rng(seed)
    e = ls.emit(rng.random(n), rng.random((n, 2)), rng.random((n, 2)))
    q = e.p - C                                            # start inside the sphere
    b = (q * e.d).sum(1)
    t = -b + np.sqrt(b * b - (q * q).sum(1) + R * R)
    x1 = e.p + e.d * t[:, None]
    return luminance(e.beta) * ls.emission_reaches(e.light, e.p, x1)


def _analytic_flux(r, R, sphere, intensity=2.0):
    """Sphere: all of its power 4πI. Disk: a receiver at distance R facing the centre sees a
    coaxial disk of radiance L = I/(πr²): E = π·L·r²/(R² + r²) = I/(R² + r²), times 4πR²."""
    if sphere:
        return 4 * np.pi * intensity
    return 4 * np.pi * R * R * intensity / (R * R + r * r)


def _assert_mean(samples, expect):
    """Z-test of the mean, or (for a constant estimator: light tracing of a sphere light, whose
    every line carries 4πI) equality up to rounding."""
    if samples.std() <= 1e-9 * abs(samples.mean()):
        np.testing.assert_allclose(samples.mean(), expect, rtol=1e-9)
    else:
        assert z_test_mean(samples, expect) > 1e-3, (samples.mean(), expect)


@pytest.mark.parametrize("sphere", [True, False])
@pytest.mark.parametrize("R", [0.7, 3.0])
def test_point_light_flux_is_the_same_by_next_event_and_light_tracing(sphere, R):
    """r = 0.5: the disk's flux through a sphere of radius 0.7 is 34 % below 4πI."""
    ls = lightset(points=soft_point(0.5, sphere))
    nee, emit = _nee_flux_through_sphere(ls, R), _emit_flux_through_sphere(ls, R)
    expect = _analytic_flux(0.5, R, sphere)
    _assert_mean(nee, expect)
    _assert_mean(emit, expect)
    if not sphere and R == 0.7:
        assert expect < 0.7 * 4 * np.pi * 2.0                   # the test can tell disk from sphere


@pytest.mark.parametrize("sphere", [True, False])
def test_spot_light_flux_is_the_same_by_next_event_and_light_tracing(sphere):
    ls = lightset(points=soft_point(0.4, sphere, spot_deg=60, blend=0.4))
    nee, emit = _nee_flux_through_sphere(ls, 1.5), _emit_flux_through_sphere(ls, 1.5)
    se = np.sqrt(nee.var() / len(nee) + emit.var() / len(emit))
    assert abs(nee.mean() - emit.mean()) < 3.5 * se, (nee.mean(), emit.mean(), se)
    assert emit.mean() < 0.5 * 4 * np.pi * 2.0


def test_wrong_emission_start_is_detected():
    """Starting the disk light's lines on its sphere instead of the closest point (and so
    lighting receivers the facing disk does not cover) is measurably too bright."""
    ls = lightset(points=soft_point(0.5, False))
    ls.pt_sphere[:] = True                                       # emit as a sphere …
    emit = _emit_flux_through_sphere(ls, 0.7)
    assert z_test_mean(emit, _analytic_flux(0.5, 0.7, False)) < 1e-6


def test_spread_light_power_by_next_event_and_light_tracing():
    """P = π·L·A with and without spread: through a hemisphere about the light (NEE) and as
    the mean light-tracing throughput."""
    al = _spread_light(np.radians(50))
    ls = lightset(areas=al)
    L, A = luminance(np.array([1.0, 2.0, 3.0])), 4 * 0.8 * 0.5
    expect = np.pi * L * A
    rng = np.random.default_rng(5)
    e = ls.emit(rng.random(200_000), rng.random((200_000, 2)), rng.random((200_000, 2)))
    assert z_test_mean(luminance(e.beta), expect) > 1e-3
    n, R = 400_000, 4.0
    nrm = al.normal.astype(np.float64)[0]
    w = rng.normal(size=(n, 3))
    w /= np.linalg.norm(w, axis=1, keepdims=True)
    w *= np.sign(w @ nrm)[:, None]                               # the front hemisphere
    x = al.center.astype(np.float64)[0] + R * w
    s = ls.illuminate(x, rng.random(n), rng.random((n, 2)))
    flux = 2 * np.pi * R * R * luminance(s.Li) * np.maximum(-(s.wi * w).sum(1), 0) \
        / np.where(s.valid, s.pdf_w, 1) * s.valid
    assert z_test_mean(flux, expect) > 1e-3, (flux.mean(), expect)


def test_sun_cone_irradiance_by_next_event_and_light_tracing():
    """Irradiance on a plane at 40° to the sun: NEE and the light-traced flux through a disk."""
    half = np.radians(10.0)
    d = np.array([0.0, -1.0, 0.0])
    ls = lightset(suns=SunLights([d], [[3, 3, 3]], [2 * half], [1]))
    nrm = np.array([np.sin(np.radians(40)), np.cos(np.radians(40)), 0.0])
    rng = np.random.default_rng(6)
    n = 200_000
    s = ls.illuminate(np.zeros((n, 3)), rng.random(n), rng.random((n, 2)))
    nee = luminance(s.Li) * np.maximum(s.wi @ nrm, 0) / s.pdf_w
    # ∫_cone L·(ω·n) dω = L·π·sin²(half)·(axis·n) = E·cos 40° (the cone is inside n's hemisphere)
    expect = 3 * np.cos(np.radians(40))
    assert z_test_mean(nee, expect) > 1e-3, (nee.mean(), expect)
    e = ls.emit(rng.random(n), rng.random((n, 2)), rng.random((n, 2)))
    t = -(e.p @ nrm) / (e.d @ nrm)
    hit = e.p + e.d * t[:, None]
    rd = 0.5                                                     # receiver disk radius
    flux = luminance(e.beta) * (np.linalg.norm(hit, axis=1) <= rd)
    assert z_test_mean(flux / (np.pi * rd * rd), expect) > 1e-3


def test_radius_zero_keeps_the_delta_light_samples():
    """Radius 0 / angle 0 / spread π take the delta and plain code paths bit for bit."""
    pts = PointLights([C], [[2, 2, 2]], [[0, -1, 0]], [-1.0], [0.0], [0.0], [1], [True])
    ls = lightset(points=pts, suns=SunLights([[0, -1, 0]], [[1, 1, 1]], [0.0], [1]))
    x = np.random.default_rng(7).random((100, 3))
    s = ls.illuminate(x, np.linspace(0, 0.999, 100), np.random.default_rng(8).random((100, 2)))
    assert s.is_delta.all()
    pt = ls.kind[s.light] == 0
    np.testing.assert_array_equal(s.p[pt], np.broadcast_to(C.astype(np.float32).astype(float), s.p[pt].shape))


# --------------------------------------------------------------------------- transport
def soft_box(sphere: bool, width=24, height=18) -> SceneDescription:
    """The point-lit box with a radius 0.15 point light and a radius 0.1 spot."""
    d = point_lit_box(width, height)
    pl = d.point_lights
    return d.replace(point_lights=PointLights(pl.position, pl.intensity, pl.direction, pl.cos_half_angle,
                                              pl.blend, [0.15, 0.1], pl.object_ids, [sphere, sphere]))


def spread_cornell(width=24, height=18) -> SceneDescription:
    d = cornell_box(width, height, "area")
    a = d.area_lights
    return d.replace(area_lights=AreaLights(a.center, a.axis_u, a.axis_v, a.normal, a.radiance, a.shape,
                                            a.object_ids, np.full(len(a.object_ids), np.radians(45))))


@pytest.mark.parametrize("name, make", [
    ("sphere", lambda: soft_box(True)),
    ("disk", lambda: soft_box(False)),
    ("spread", lambda: spread_cornell()),
])
def test_bdpt_agrees_with_path(name, make):
    """BDPT's light-traced strategies (emit, with the soft-falloff test) and its MIS weights
    against PATH, which reaches these lights by next-event estimation only."""
    path = _renders(make(), "PATH", 10, 32, seed0=1000)
    bdpt = _renders(make(), "BDPT", 10, 16, seed0=2000)
    _assert_agree(path, bdpt)
