"""Mirrors and glass through PATH, BDPT and ERCUTS (issue 15).

* A perfect mirror at 45° reflecting an emitter: every integrator returns F·Le exactly
  (Schlick's F at the mirror's reflectance; the path is found only by BSDF sampling, so it
  must get weight 1).
* A clear glass slab in front of an emitter, seen at normal incidence: a camera path reaches
  the emitter with probability T = (1 − F)/(1 + F) (incoherent multiple reflections,
  F = 0.04) and carries exactly Le then — the 1/η² of entering and the η² of leaving cancel —
  so the image mean is a Bernoulli mean with a known standard error.
* The specular box (a mirror block, a glass ball, caustics): ERCUTS's and BDPT's image
  energies agree with PATH's (seeds' spread; ERCUTS within 2 % on top).
"""
from __future__ import annotations

import numpy as np
import pytest

from ercuts_core.bsdf import schlick_fresnel
from ercuts_core.description import CameraDesc, MaterialTable, MeshTable, SceneDescription
from ercuts_core.render import render
from ercuts_core.scenes import look_at, specular_box
from ercuts_core.settings import RenderSettings

LE = 2.0
W, H = 16, 12


def _quad(p):
    return np.array(p, np.float64), np.array([[0, 1, 2], [0, 2, 3]])


def _scene(quads, mats: MaterialTable) -> SceneDescription:
    """Quads (4 corners, material) seen by an orthographic camera at z = 5 looking down −z."""
    pos, tris, mat, obj = [], [], [], []
    for i, (corners, m) in enumerate(quads):
        p, t = _quad(corners)
        tris.append(t + 4 * i)
        pos.append(p)
        mat += [m, m]
        obj += [i, i]
    cam = CameraDesc(look_at((0, 0, 5), (0, 0, 0)), W, H, projection="ORTHO", ortho_scale=1.0)
    mesh = MeshTable(np.concatenate(pos), np.concatenate(tris), mat, obj)
    return SceneDescription(mesh, mats, cam, object_names=tuple(f"Q{i}" for i in range(len(quads))))


def mirror_scene(R=(0.9, 0.6, 0.3)) -> SceneDescription:
    """A mirror through the origin with normal (0, 1, 1)/√2 turns the camera rays (0, 0, −1)
    into (0, 1, 0), toward an emitter at y = 3 facing down."""
    mats = MaterialTable(("Mirror", "Lamp"), [R, [0, 0, 0]], [0, 1], [1, 0], [0.5, 0],
                         [[0, 0, 0], [LE] * 3])
    mirror = [(-2, 2, -2), (-2, -2, 2), (2, -2, 2), (2, 2, -2)]
    lamp = [(-6, 3, -6), (6, 3, -6), (6, 3, 6), (-6, 3, 6)]
    return _scene([(mirror, 0), (lamp, 1)], mats)


def slab_scene(thickness=0.5) -> SceneDescription:
    """A glass slab z ∈ [−thickness, 0] (IOR 1.5; front and back faces, outward normals)
    in front of an emitter at z = −2 facing +z."""
    mats = MaterialTable(("Glass", "Lamp"), [[1, 1, 1], [0, 0, 0]], [0, 1], [0, 0], [0.5, 0],
                         [[0, 0, 0], [LE] * 3], (), [1, 0], [1.5, 1.5])
    z = -thickness
    front = [(-3, -3, 0), (3, -3, 0), (3, 3, 0), (-3, 3, 0)]           # normal +z
    back = [(-3, -3, z), (-3, 3, z), (3, 3, z), (3, -3, z)]            # normal −z
    lamp = [(-9, -9, -2), (9, -9, -2), (9, 9, -2), (-9, 9, -2)]
    return _scene([(front, 0), (back, 0), (lamp, 1)], mats)


@pytest.mark.parametrize("integrator", ["PATH", "BDPT", "ERCUTS"])
def test_mirror_reflects_the_emitter_exactly(integrator):
    R = np.array([0.9, 0.6, 0.3])
    r = render(mirror_scene(R), RenderSettings(integrator=integrator, samples=2, rough_samples=2,
                                               direct_samples=2, max_depth=4, seed=3))
    F = schlick_fresnel(np.array([np.sqrt(0.5)]), R[None, :], np.ones((1, 3)))[0]
    np.testing.assert_allclose(r.image[..., :3].reshape(-1, 3), np.tile(F * LE, (W * H, 1)), rtol=2e-5)


def mirror_and_lights(R=(0.9, 0.6, 0.3)) -> SceneDescription:
    """The mirror of :func:`mirror_scene` showing, instead of an emissive mesh, an area light
    (rectangle, x < 0 half of the view) and a sphere light (x > 0 half)."""
    from dataclasses import replace
    from ercuts_core.description import AreaLights, PointLights
    mats = MaterialTable(("Mirror",), [R], [0], [1], [0.5], np.zeros((1, 3)))
    desc = _scene([([(-2, 2, -2), (-2, -2, 2), (2, -2, 2), (2, 2, -2)], 0)], mats)
    area = AreaLights([[-1.25, 3, 0]], [[1.0, 0, 0]], [[0, 0, 1.0]], [[0, -1, 0]], [[LE] * 3], [0], [1])
    # sphere light radius 2 at y = 6 (I = L·π r²), covering x ∈ [0.4, 0.6] of the mirror's view
    r = 2.0
    pts = PointLights([[2.5, 6, 0]], [[LE * np.pi * r * r] * 3], [[0, -1, 0]], [-1.0], [0.0], [r], [1], [True])
    return replace(desc, area_lights=area, point_lights=pts)


@pytest.mark.parametrize("integrator", ["PATH", "BDPT", "ERCUTS"])
def test_mirror_shows_area_and_sphere_lights(integrator):
    R = np.array([0.9, 0.6, 0.3])
    r = render(mirror_and_lights(R), RenderSettings(integrator=integrator, samples=2, rough_samples=2,
                                                    direct_samples=2, max_depth=4, seed=3))
    img = r.image[..., :3]
    F = schlick_fresnel(np.array([np.sqrt(0.5)]), R[None, :], np.ones((1, 3)))[0]
    # ortho view x ∈ [−0.5, 0.5]: the area light covers x ∈ [−2.25, −0.25] (columns 0–3), the
    # sphere (centre x = 2.5, r = 2 at y = 6; the reflected rays go straight up) x ≥ 0.5: none
    np.testing.assert_allclose(img[:, :4].reshape(-1, 3), np.tile(F * LE, (4 * H, 1)), rtol=2e-5)
    np.testing.assert_allclose(img[:, 5:], 0.0, atol=1e-7)


@pytest.mark.parametrize("integrator", ["PATH", "BDPT", "ERCUTS"])
def test_glass_slab_transmits_one_minus_f_over_one_plus_f(integrator):
    spp = 64
    r = render(slab_scene(), RenderSettings(integrator=integrator, samples=spp, rough_samples=4,
                                            direct_samples=spp, max_depth=64, seed=5))
    img = r.image[..., :3].astype(np.float64)
    assert np.isfinite(img).all()
    F = 0.04
    T = (1 - F) / (1 + F)
    n = W * H * spp
    se = LE * np.sqrt(T * (1 - T) / n)
    mean = img.mean()
    assert abs(mean - LE * T) < 4.5 * se, (mean, LE * T, se)
    # and no light is lost or added (a wrong η² factor would be off by 2.25×)
    assert np.allclose(img.mean(axis=(0, 1)), mean, rtol=1e-6)


def _energies(integrator, k, **kw):
    out = []
    for i in range(k):
        r = render(specular_box(40, 30), RenderSettings(integrator=integrator, seed=100 + i,
                                                        max_depth=24, **kw))
        assert np.isfinite(r.image).all()
        out.append(float(r.image[..., :3].astype(np.float64).mean()))
    return np.array(out)


def test_specular_box_energy_agrees_across_integrators():
    k = 4
    path = _energies("PATH", k, samples=128)
    bdpt = _energies("BDPT", k, samples=32)
    ercuts = _energies("ERCUTS", k, rough_samples=8, direct_samples=64)
    se = lambda a: a.std(ddof=1) / np.sqrt(len(a))                       # noqa: E731
    print("PATH", path.mean(), se(path), "BDPT", bdpt.mean(), se(bdpt), "ERCUTS", ercuts.mean(), se(ercuts))
    s_pb = np.hypot(se(path), se(bdpt))
    assert abs(bdpt.mean() - path.mean()) < 4 * s_pb
    s_pe = np.hypot(se(path), se(ercuts))
    assert abs(ercuts.mean() / path.mean() - 1) < 0.02 + 4 * s_pe / path.mean()
