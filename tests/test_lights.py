"""Lights: pdf consistency between illuminate and hits, emitted power, irradiance, spot falloff."""
from __future__ import annotations

import numpy as np
import pytest

from ercuts_core import AreaLights, MaterialTable, MeshTable, PointLights, SunLights
from ercuts_core.description import SHAPE_ELLIPSE, SHAPE_RECT, SceneDescription
from ercuts_core.lights import AREA
from ercuts_core.sampling import luminance
from ercuts_core.scene import BuiltScene
from ercuts_core.scenes import _camera
from ercuts_core.validate import sanitize

RNG = np.random.default_rng(12)


def built(area=None, points=None, suns=None, emissive=False, world=(0, 0, 0)):
    pos = np.array([[-1, 0, -1], [1, 0, -1], [1, 0, 1], [-1, 0, 1], [-0.3, 1, 0], [0.3, 1, 0], [0, 1.2, 0.4]])
    tris = np.array([[0, 2, 1], [0, 3, 2], [4, 5, 6]])
    mats = MaterialTable(["Grey", "Lamp"], [[0.5] * 3, [0.5] * 3], [1, 1], [0, 0], [0, 0],
                         [[0, 0, 0], [2.0, 3.0, 1.0] if emissive else [0, 0, 0]])
    kw = {}
    if area is not None:
        kw["area_lights"] = area
    if points is not None:
        kw["point_lights"] = points
    if suns is not None:
        kw["sun_lights"] = suns
    d = SceneDescription(MeshTable(pos, tris, [0, 0, 1], [0, 0, 1]), mats, _camera((0, 1, 3), (0, 0, 0), 8, 6),
                         world_radiance=np.array(world, float), object_names=("Floor", "Tri", "L"), **kw)
    return BuiltScene(sanitize(d).desc)


def disk(shape, radiance=(1.0, 2.0, 3.0), r=0.5, h=1.0):
    return AreaLights([[0, h, 0]], [[r, 0, 0]], [[0, 0, r * 0.6 if shape == SHAPE_RECT else r]],
                      [[0, -1, 0]], [radiance], [shape], [2])


@pytest.mark.parametrize("shape,area", [(SHAPE_RECT, 4 * 0.5 * 0.3), (SHAPE_ELLIPSE, np.pi * 0.25)])
def test_area_light_emitted_power_is_pi_L_A(shape, area):
    ls = built(area=disk(shape)).lights
    n = 200_000
    e = ls.emit(RNG.random(n), RNG.random((n, 2)), RNG.random((n, 2)))
    y = luminance(e.beta)
    expect = np.pi * luminance(np.array([1.0, 2.0, 3.0])) * area
    # Uniform-area, cosine-direction sampling has constant weight: exact per sample
    # (up to the float32 storage of the light's axes).
    np.testing.assert_allclose(y, expect, rtol=1e-6)
    pdf_pos, pdf_dir = ls.pdf_emit(e.light, e.p, e.n, e.d)
    np.testing.assert_allclose(pdf_pos, e.pdf_pos)
    np.testing.assert_allclose(pdf_dir, e.pdf_dir)


def test_emissive_triangle_power_is_two_pi_L_A_and_pdfs_agree():
    ls = built(emissive=True).lights
    n = 100_000
    e = ls.emit(RNG.random(n), RNG.random((n, 2)), RNG.random((n, 2)))
    area = ls.tri_area[0]
    np.testing.assert_allclose(luminance(e.beta).mean(), 2 * np.pi * area * luminance(np.array([2.0, 3, 1])),
                               rtol=1e-9)
    assert abs((e.d @ ls.tri_n[0] > 0).mean() - 0.5) < 0.01     # both sides emit
    pdf_pos, pdf_dir = ls.pdf_emit(e.light, e.p, e.n, e.d)
    np.testing.assert_allclose(pdf_dir, e.pdf_dir)


def test_illuminate_pdf_equals_pdf_on_hit_for_triangles():
    sc = built(emissive=True)
    ls = sc.lights
    n = 5000
    x = np.c_[RNG.uniform(-1, 1, n), np.zeros(n), RNG.uniform(-1, 1, n)]
    s = ls.illuminate(x, RNG.random(n), RNG.random((n, 2)))
    prim = np.full(n, 2)
    pdf_hit = ls.pdf_illuminate_tri(x, prim, s.p, ls.tri_n[np.zeros(n, int)])
    np.testing.assert_allclose(s.pdf_w, pdf_hit, rtol=1e-10)


@pytest.mark.parametrize("h,r", [(1.0, 0.5), (2.0, 0.1)])
def test_disk_light_irradiance_matches_analytic(h, r):
    """E at the point below a facing disk of radiance L: π·L·r²/(r²+h²)."""
    ls = built(area=disk(SHAPE_ELLIPSE, radiance=(1, 1, 1), r=r, h=h)).lights
    n = 200_000
    x = np.zeros((n, 3))
    s = ls.illuminate(x, RNG.random(n), RNG.random((n, 2)))
    est = s.Li[:, 0] * np.maximum(s.wi[:, 1], 0) / s.pdf_w
    expect = np.pi * r * r / (r * r + h * h)
    assert abs(est.mean() - expect) < 4 * est.std() / np.sqrt(n)


def test_area_light_is_one_sided():
    ls = built(area=disk(SHAPE_RECT)).lights
    x = np.array([[0.0, 2.0, 0.0]])  # above the downward-facing light
    s = ls.illuminate(x, np.array([0.5]), np.array([[0.5, 0.5]]))
    assert not s.valid[0] and luminance(s.Li)[0] == 0


def test_spot_falloff_and_point_light_inverse_square():
    pts = PointLights([[0, 1, 0], [0, 1, 0]], [[2, 2, 2], [2, 2, 2]], [[0, -1, 0], [0, -1, 0]],
                      [-1, np.cos(np.radians(30))], [0, 0.5], [0, 0], [2, 2])
    ls = built(points=pts).lights
    x = np.array([[0, 0, 0], [np.tan(np.radians(29.0)), 0, 0], [np.tan(np.radians(31)), 0, 0]])
    w = x - [0, 1, 0]
    w /= np.linalg.norm(w, axis=1, keepdims=True)
    f = ls.spot_factor(np.array([1, 1, 1]), w)
    assert f[0] == 1.0 and 0 < f[1] < 1 and f[2] == 0.0
    # smoothstep inside the blend band: t = (cos − cos½)/((1 − cos½)·blend)
    c, ch = np.cos(np.radians(29.0)), np.cos(np.radians(30))
    t = (c - ch) / ((1 - ch) * 0.5)
    assert f[1] == pytest.approx(t * t * (3 - 2 * t), rel=1e-5)   # float32 storage
    s = ls.illuminate(np.array([[0, -1.0, 0]] * 200), np.linspace(0, 0.999, 200), RNG.random((200, 2)))
    pt = s.light == 0
    np.testing.assert_allclose(s.Li[pt], 2 / 4.0)


def test_sun_irradiance_and_pdfs():
    suns = SunLights([[0, -1, 0]], [[3, 3, 3]], [0.0], [2])
    ls = built(suns=suns).lights
    s = ls.illuminate(np.zeros((4, 3)), RNG.random(4), RNG.random((4, 2)))
    assert s.is_delta.all() and np.allclose(s.Li, 3) and np.allclose(s.wi, [0, 1, 0])
    e = ls.emit(RNG.random(1000), RNG.random((1000, 2)), RNG.random((1000, 2)))
    # Power through the scene disk: E·πR².
    np.testing.assert_allclose(luminance(e.beta).mean(), 3 * np.pi * ls.radius**2)


def test_power_based_selection():
    area = disk(SHAPE_RECT)
    ls = built(area=area, emissive=True).lights
    assert ls.n_lights == 2
    pw = ls.distribution.pmf
    p_area = np.pi * ls.ar_area[0] * luminance(ls.ar_L[0])
    p_tri = 2 * np.pi * ls.tri_area[0] * luminance(ls.tri_L[0])
    np.testing.assert_allclose(pw[ls.kind == AREA][0], p_area / (p_area + p_tri))
