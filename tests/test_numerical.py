"""Numerical robustness: no NaN/Inf reaches the film (grazing angles, roughness 0),
coincident and co-planar VPLs in the light tree and lightcuts, and a VPL at distance ~0
from a shading point (the geometry clamp bounds it; the removed energy is counted)."""
from __future__ import annotations

import numpy as np
import pytest

from ercuts_core import MaterialTable, MeshTable, PointLights, RenderSettings, render
from ercuts_core.description import SceneDescription
from ercuts_core.film import Film
from ercuts_core.camera import Window
from ercuts_core.integrators.ercuts.light_tree import build_light_tree
from ercuts_core.integrators.ercuts.lightcuts import ShadingPoints, brute_force, lightcut
from ercuts_core.scenes import _camera


def test_film_replaces_and_counts_nonfinite_samples():
    film = Film(Window(0, 0, 2, 1))
    film.add_samples(np.array([0, 1, 1]), np.array([[1.0, 1, 1], [np.nan, 0, 0], [np.inf, 1, 1]]),
                     np.ones(3))
    assert film.nonfinite == 2
    np.testing.assert_array_equal(film.color, [[1, 1, 1], [0, 0, 0]])


def grazing_mirror_scene(roughness: float) -> SceneDescription:
    """A large metallic GGX floor seen at ~0.5° above the horizon, lit by a low point light."""
    pos = np.array([[-50, -50, 0], [50, -50, 0], [50, 50, 0], [-50, 50, 0]], float)
    mesh = MeshTable(pos, [[0, 1, 2], [0, 2, 3]], [0, 0], [0, 0])
    mats = MaterialTable(("Mirror",), [[0.9, 0.9, 0.9]], [roughness], [1.0], [0.5], [[0, 0, 0]])
    light = PointLights([[0, 20, 0.05]], [[50, 50, 50]], [[0, 0, -1]], [-1], [0], [0], [1])
    cam = _camera((0, -20, 0.1), (0, 20, -0.25), 12, 8)
    return SceneDescription(mesh, mats, cam, point_lights=light, object_names=("Floor", "Lamp"),
                            world_radiance=[0.1, 0.1, 0.1])


@pytest.mark.parametrize("integrator", ["PATH", "BDPT", "ERCUTS"])
@pytest.mark.parametrize("roughness", [0.0, 1e-4, 0.3])
def test_no_nonfinite_samples_at_grazing_angles_and_roughness_zero(integrator, roughness):
    s = RenderSettings(integrator=integrator, samples=4, max_depth=4, chain_length=5, e1_samples=16)
    r = render(grazing_mirror_scene(roughness), s)
    assert r.stats["nonfinite_samples"] == 0
    assert np.isfinite(r.image).all() and r.image[..., :3].max() > 0
    for aov in r.aovs.values():
        assert np.isfinite(aov).all()


# --------------------------------------------------------------------------- VPLs

def floor_points(x: np.ndarray) -> ShadingPoints:
    """Diffuse (albedo 0.5) receivers facing +z, nothing occludes."""
    n = len(x)
    up = np.tile([0.0, 0.0, 1.0], (n, 1))
    alb = np.full((n, 3), 0.5)

    def eval_f(i, wi):
        return alb[i] / np.pi * (wi[:, 2] > 0)[:, None]

    return ShadingPoints(x, up, up.copy(), alb / np.pi, eval_f, lambda i, q, qn: np.ones(len(i), bool))


def _cut_vs_brute(pos, nrm, inten, pts, clamp):
    tree = build_light_tree(pos, nrm, inten, seed=1)
    res = lightcut(tree, pos, nrm, inten, pts, max_error=0.02, max_cut_size=len(pos) * 2, clamp=clamp)
    exact = brute_force(pos, nrm, inten, pts, clamp=clamp)
    return res, exact


@pytest.mark.parametrize("clamp", [0.0, 0.5])
def test_coincident_vpls(clamp):
    """1000 VPLs at one point: the tree's clusters have zero extent; the cut equals the sum."""
    rng = np.random.default_rng(3)
    pos = np.tile([0.0, 0.0, 2.0], (1000, 1))
    nrm = np.tile([0.0, 0.0, -1.0], (1000, 1))
    inten = rng.random((1000, 3))
    pts = floor_points(np.c_[rng.random((64, 2)) * 4 - 2, np.zeros(64)])
    res, exact = _cut_vs_brute(pos, nrm, inten, pts, clamp)
    assert np.isfinite(res.radiance).all() and (exact > 0).all()
    np.testing.assert_allclose(res.radiance, exact, rtol=0.05)


def test_coplanar_vpls_and_receivers_give_zero_not_nan():
    """VPLs in the receivers' plane with the same normal: every cosine is 0 on both sides."""
    rng = np.random.default_rng(4)
    pos = np.c_[rng.random((500, 2)) * 4 - 2, np.zeros(500)]
    nrm = np.tile([0.0, 0.0, 1.0], (500, 1))
    inten = rng.random((500, 3))
    pts = floor_points(np.c_[rng.random((32, 2)) * 4 - 2, np.zeros(32)])
    res, exact = _cut_vs_brute(pos, nrm, inten, pts, clamp=0.0)
    assert np.isfinite(res.radiance).all() and np.isfinite(exact).all()
    assert res.radiance.max() == 0 and exact.max() == 0


def test_coplanar_vpls_facing_a_receiver_plane():
    """Co-planar VPLs (a ceiling) over co-planar receivers: cut within the error of brute force."""
    rng = np.random.default_rng(5)
    pos = np.c_[rng.random((2000, 2)) * 4 - 2, np.full(2000, 1.0)]
    nrm = np.tile([0.0, 0.0, -1.0], (2000, 1))
    inten = rng.random((2000, 3)) * 0.01
    pts = floor_points(np.c_[rng.random((64, 2)) * 4 - 2, np.zeros(64)])
    res, exact = _cut_vs_brute(pos, nrm, inten, pts, clamp=0.0)
    assert np.isfinite(res.radiance).all()
    np.testing.assert_allclose(res.radiance.sum(axis=1), exact.sum(axis=1), rtol=0.1)


@pytest.mark.parametrize("distance", [0.0, 1e-12, 1e-6])
def test_vpl_at_distance_zero_is_clamped_and_its_energy_counted(distance):
    """G = cosθ_v/d² → ∞ as d → 0; the clamp G ≤ gmax bounds it and reports what it removed.

    The VPL sits just above the point, facing it: M·G·I with G clamped to gmax is at most
    (0.5/π)·gmax·I, and the removed energy M·(G − gmax)·I is counted in ``clamped_energy``
    (finite for every d > 0). At d = 0 exactly the direction is undefined: the pair
    contributes nothing (no NaN) and nothing is clamped."""
    gmax = 4.0
    x = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]])
    pos = np.array([[0.0, 0.0, distance], [5.0, 5.0, 2.0]])
    nrm = np.array([[0.0, 0.0, -1.0], [0.0, 0.0, -1.0]])
    inten = np.array([[1.0, 1.0, 1.0], [1.0, 1.0, 1.0]])
    pts = floor_points(x)
    with np.errstate(all="raise"):
        res, exact = _cut_vs_brute(pos, nrm, inten, pts, clamp=gmax)
    assert np.isfinite(res.radiance).all() and np.isfinite(exact).all()
    # Point 0 gets at most the clamped value from the close VPL (+ the far one's small share).
    assert res.radiance[0, 0] <= 0.5 / np.pi * gmax * 1.0 + 0.01
    if distance > 0:
        assert res.radiance[0, 0] >= 0.5 / np.pi * gmax * 0.99
        assert 0 < res.clamped_energy < np.inf
    else:
        assert res.radiance[0, 0] < 0.01 and res.clamped_energy == 0


def test_ercuts_reports_the_clamped_energy():
    from ercuts_core.scenes import cornell_box
    r = render(cornell_box(24, 18), RenderSettings(rough_samples=2, max_depth=4, chain_length=10,
                                                   e1_samples=16, clamp=0.2))
    assert r.stats["clamped_energy"] > 0 and np.isfinite(r.stats["clamped_energy"])
    assert r.stats["nonfinite_samples"] == 0
