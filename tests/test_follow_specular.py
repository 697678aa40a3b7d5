"""ERCUTS's gather through perfect mirrors and smooth glass (algorithm.md §G.3).

The gather's shading points follow the camera through purely delta surfaces to the first
other surface (``vpl.follow_specular``); the direct-light passes then path-trace only the
complement (``paths='direct_and_late_delta'``), and P leaves out every delta path (BDPT's
``delta_indirect``). Checked here:

* geometry and weights of the moved points: a 45° mirror shows a diffuse ceiling; the points
  land on it with weight F (Schlick at 45°), exactly; through a glass slab the mean weight of
  the points behind it is the analytic transmittance (Bernoulli standard error);
* the two path sets agree between integrators: BDPT restricted to the traced set renders the
  same energy as PATH restricted to it, and BDPT's counters ``delta_indirect`` and
  ``traced_indirect`` equal PATH's indirect light of the delta and traced sets (standard
  errors of K independent renders);
* the whole: ERCUTS with the gather following mirrors and glass renders the mirror-and-glass
  room with the energy of PATH, as it did before (the ablation ``FOLLOW_SPECULAR = False``).
"""
from __future__ import annotations

import numpy as np
import pytest

from ercuts_core import RenderSettings, render
from ercuts_core.bsdf import fresnel_dielectric, schlick_fresnel
from ercuts_core.description import CameraDesc, MaterialTable, MeshTable, SceneDescription
from ercuts_core.film import Film
from ercuts_core.integrators.bdpt import BDPTIntegrator
from ercuts_core.integrators.ercuts import integrator as ercuts_integrator
from ercuts_core.integrators.ercuts.vpl import build_gbuffer, first_hits_only, follow_specular
from ercuts_core.integrators.path import PathIntegrator
from ercuts_core.sampling import luminance
from ercuts_core.scene import BuiltScene
from ercuts_core.scenes import look_at, mirror_glass_room

W, H = 16, 12


def _scene(quads, mats: MaterialTable) -> SceneDescription:
    """Quads (4 corners, material) seen by an orthographic camera at z = 5 looking down −z."""
    pos, tris, mat = [], [], []
    for i, (corners, m) in enumerate(quads):
        pos.append(np.array(corners, np.float64))
        tris.append(np.array([[0, 1, 2], [0, 2, 3]]) + 4 * i)
        mat += [m, m]
    cam = CameraDesc(look_at((0, 0, 5), (0, 0, 0)), W, H, projection="ORTHO", ortho_scale=1.0)
    mesh = MeshTable(np.concatenate(pos), np.concatenate(tris), mat, np.repeat(np.arange(len(quads)), 2))
    return SceneDescription(mesh, mats, cam, object_names=tuple(f"Q{i}" for i in range(len(quads))))


def test_points_on_a_mirror_move_to_what_it_shows_with_weight_f():
    """A mirror through the origin with normal (0, 1, 1)/√2 turns the camera rays (0, 0, −1)
    into (0, 1, 0), toward a diffuse ceiling at y = 3 facing down."""
    R = np.array([0.9, 0.6, 0.3])
    mats = MaterialTable(("Mirror", "Ceiling"), [R, [0.5, 0.5, 0.5]], [0, 1], [1, 0], [0.5, 0.5],
                         [[0, 0, 0], [0, 0, 0]])
    mirror = [(-2, 2, -2), (-2, -2, 2), (2, -2, 2), (2, 2, -2)]
    ceiling = [(-6, 3, -6), (6, 3, -6), (6, 3, 6), (-6, 3, 6)]
    scene = BuiltScene(_scene([(mirror, 0), (ceiling, 1)], mats))
    assert scene.has_delta
    g, _ = build_gbuffer(scene, 2, np.random.default_rng(0))
    assert g.weight is None and g.valid.all()
    first = g.p.copy()
    np.testing.assert_allclose(first[:, 1] + first[:, 2], 0.0, atol=1e-9)   # on the mirror
    f = follow_specular(scene, g, np.random.default_rng(1))
    assert f is g and f.through.all() and f.valid.all()
    assert not first_hits_only(f).valid.any()                               # E1 sees none of them
    np.testing.assert_allclose(f.p[:, 1], 3.0, atol=1e-6)                   # on the ceiling
    # straight above (up to the ray offset off the mirror, tracer.epsilon ≈ 1e-5 here)
    np.testing.assert_allclose(f.p[:, [0, 2]], first[:, [0, 2]], atol=1e-4)
    np.testing.assert_allclose(f.wo, np.tile([0.0, -1.0, 0.0], (len(f.p), 1)), atol=1e-9)
    np.testing.assert_allclose(f.ns, np.tile([0.0, -1.0, 0.0], (len(f.p), 1)), atol=1e-9)
    F = schlick_fresnel(np.array([np.sqrt(0.5)]), R[None, :], np.ones((1, 3)))[0]
    np.testing.assert_allclose(f.weight, np.tile(F, (len(f.p), 1)), rtol=1e-6)   # float geometry


def test_points_on_glass_see_through_with_the_transmittance_as_mean_weight():
    """A clear slab (IOR 1.5) over a diffuse floor, seen head-on: a point reaches the floor
    with probability (1 − F)²·Σ(F²)^k (the reflections inside the slab: a Bernoulli event per
    point; reflected paths leave toward the camera side and are dropped) and then carries
    weight exactly 1 (the 1/η² of entering and the η² of leaving cancel)."""
    mats = MaterialTable(("Glass", "Floor"), [[1, 1, 1], [0.5, 0.5, 0.5]], [0, 1], [0, 0], [0.5, 0.5],
                         [[0, 0, 0], [0, 0, 0]], (), [1, 0], [1.5, 1.5])
    front = [(-3, -3, 0), (3, -3, 0), (3, 3, 0), (-3, 3, 0)]
    back = [(-3, -3, -0.5), (-3, 3, -0.5), (3, 3, -0.5), (3, -3, -0.5)]
    floor = [(-9, -9, -2), (9, -9, -2), (9, 9, -2), (-9, 9, -2)]
    scene = BuiltScene(_scene([(front, 0), (back, 0), (floor, 1)], mats))
    g, _ = build_gbuffer(scene, 64, np.random.default_rng(2))
    f = follow_specular(scene, g, np.random.default_rng(3))
    on_floor = f.valid & np.isclose(f.p[:, 2], -2.0, atol=1e-6)
    assert not (f.valid & ~on_floor).any()             # nothing else can be reached
    np.testing.assert_allclose(f.weight[on_floor], 1.0, rtol=1e-9)
    Fr, _ = fresnel_dielectric(np.array([1.0]), np.array([1.5]))
    Fr = float(Fr[0])
    T = (1 - Fr) ** 2 / (1 - Fr * Fr)
    p = on_floor.mean()
    se = np.sqrt(T * (1 - T) / len(on_floor))
    assert abs(p - T) < 4 * se, (p, T, se)


def _film_parts(integrator, window, seeds, key):
    """(K, 3) luminance sums per light pass of K one-sample passes, and the integrator."""
    out = []
    for k in seeds:
        film = Film(window)
        integrator.render_batch(film, np.arange(window.n_pixels), np.random.default_rng([key, k]))
        film.passes_done = 1
        out.append(luminance(film.light_parts().sum(axis=1)))
    return np.array(out)


def _path_sets(sets, passes: int, key: int) -> dict:
    """mirror_glass_room at 24×18: PATH's (K, 3) luminance sums per light pass of ``passes``
    one-sample passes for each path set in ``sets`` (streams ``key``, ``key`` + 1, …), and
    the built scene under 'scene'."""
    scene = BuiltScene(mirror_glass_room(24, 18))
    s = RenderSettings(seed=0)
    out = {name: _film_parts(PathIntegrator(scene, s, paths=name), scene.camera.window, range(passes), key + i)
           for i, name in enumerate(sets)}
    out["scene"] = scene
    return out


def _mean_se(a):
    return a.mean(axis=0), a.std(axis=0, ddof=1) / np.sqrt(len(a))


@pytest.mark.slow
def test_bdpt_and_path_agree_on_the_traced_and_delta_sets():
    """mirror_glass_room at 24×18: PATH and BDPT restricted to the traced set render the same
    energy, and BDPT's ``delta_indirect``/``traced_indirect`` counters equal PATH's indirect
    light of the 'delta' and 'direct_and_late_delta' sets (4 standard errors)."""
    K = 24
    path = _path_sets(("direct_and_late_delta", "delta"), K, key=1)
    path_traced, path_delta, scene = path["direct_and_late_delta"], path["delta"], path["scene"]
    s, window = RenderSettings(seed=0), scene.camera.window
    bdpt = BDPTIntegrator(scene, s, paths="direct_and_late_delta")
    bdpt_traced = _film_parts(bdpt, window, range(K // 3), 3)
    counters = []
    full = BDPTIntegrator(scene, s)
    for k in range(K // 3):
        before = (full.delta_indirect, full.traced_indirect)
        full.render_batch(Film(window), np.arange(window.n_pixels), np.random.default_rng([4, k]))
        counters.append((full.delta_indirect - before[0], full.traced_indirect - before[1]))
    counters = np.array(counters)
    m_pt, se_pt = _mean_se(path_traced.sum(axis=1))
    m_bt, se_bt = _mean_se(bdpt_traced.sum(axis=1))
    assert abs(m_pt - m_bt) < 4 * np.hypot(se_pt, se_bt), (m_pt, se_pt, m_bt, se_bt)
    m_pd, se_pd = _mean_se(path_delta[:, 2])
    m_cd, se_cd = _mean_se(counters[:, 0])
    assert abs(m_pd - m_cd) < 4 * np.hypot(se_pd, se_cd), (m_pd, se_pd, m_cd, se_cd)
    m_pi, se_pi = _mean_se(path_traced[:, 2])
    m_ci, se_ci = _mean_se(counters[:, 1])
    assert abs(m_pi - m_ci) < 4 * np.hypot(se_pi, se_ci), (m_pi, se_pi, m_ci, se_ci)
    # the traced set is a strict part of the delta paths here (the mirror and the window
    # show the room: those paths are the gather's now)
    assert m_ci < 0.8 * m_cd


@pytest.mark.slow
def test_ercuts_through_mirrors_keeps_path_tracings_energy(monkeypatch):
    """mirror_glass_room at 32×24, 3 seeds: ERCUTS with the gather following mirrors and
    glass, ERCUTS without (the ablation) and PATH have the same image energy (2 % + 4 standard
    errors of the seeds' means, as the specular box's test)."""
    desc = mirror_glass_room(32, 24)
    kw = dict(rough_samples=8, direct_samples=16, max_depth=24)

    def energies(integrator, follow, **extra):
        monkeypatch.setattr(ercuts_integrator, "FOLLOW_SPECULAR", follow)
        return np.array([float(render(desc, RenderSettings(integrator=integrator, seed=k, **extra))
                               .image[..., :3].astype(np.float64).mean()) for k in range(3)])

    path = energies("PATH", True, samples=256, max_depth=24)
    follow = energies("ERCUTS", True, **kw)
    ablation = energies("ERCUTS", False, **kw)
    se = lambda a: a.std(ddof=1) / np.sqrt(len(a))                       # noqa: E731
    print("PATH", path.mean(), se(path), "follow", follow.mean(), se(follow), "ablation", ablation.mean(), se(ablation))
    for e in (follow, ablation):
        assert abs(e.mean() / path.mean() - 1) < 0.02 + 4 * np.hypot(se(path), se(e)) / path.mean()


def test_metals_of_any_roughness_are_followed_and_hold_no_vpl():
    """``Bsdf.is_specular_or_glass`` marks every lobe without a diffuse part — a metal of any
    roughness, glass — and nothing with one: a VPL on a metal emits like a diffuse patch, not
    along the metal's lobe (tests/blender/test_gltf_cycles.py: roughness 0.6 metal stripes
    left the floor beside them 64 % short of its indirect light), so the gather follows the
    camera through metals and the chains leave them out; a half-metallic Principled keeps its
    diffuse part and its VPLs."""
    from ercuts_core.bsdf import Bsdf
    rough = [0.0, 0.3, 0.6, 1.0, 0.6, 0.6, 1.0]
    metal = [1.0, 1.0, 1.0, 1.0, 0.5, 0.0, 0.0]
    trans = [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0]
    n = len(rough)
    mats = MaterialTable([f"m{i}" for i in range(n)], [[0.8] * 3] * n, rough, metal, [0.5] * n,
                         np.zeros((n, 3)), (), trans, [1.5] * n)
    up = np.tile([0.0, 0.0, 1.0], (n, 1))
    clear = Bsdf.from_table(mats, np.arange(n), up, up).is_specular_or_glass
    assert clear.tolist() == [True, True, True, True, False, False, True]


@pytest.mark.slow
def test_the_traced_set_splits_into_direct_through_the_prefix_and_late_paths():
    """mirror_glass_room at 24×18: 'direct_and_late_delta' is the disjoint union of
    'direct_through_prefix' and 'late_delta' — PATH's two parts add up to its whole per light
    pass, BDPT's late set renders PATH's late energy, which is far from zero (4 standard
    errors). Here the late part holds most of the set (the floor seen in the mirror, the room
    through the window: 18.8 ± 1.9 of 25.8 ± 4.5 in 24 passes), so a set that doubled or
    dropped it fails; the direct part (0.36 ± 0.27: the lamp lights only the wall beside it,
    which the camera sees in no mirror) is small."""
    K = 24
    path = _path_sets(("direct_and_late_delta", "direct_through_prefix", "late_delta"), K, key=5)
    whole, direct, late = (path[k] for k in ("direct_and_late_delta", "direct_through_prefix", "late_delta"))
    scene, s = path["scene"], RenderSettings(seed=0)
    bdpt = BDPTIntegrator(scene, s, paths="late_delta")
    film = Film(scene.camera.window)
    bdpt.render_batch(film, np.arange(scene.camera.window.n_pixels), np.random.default_rng(0))
    assert film.alpha.sum() == 0.0 and not film.aov_sum          # light only: no coverage, no AOVs
    bdpt_late = _film_parts(bdpt, scene.camera.window, range(K // 3), 8)
    for c in range(3):
        m_w, se_w = _mean_se(whole[:, c])
        m_s, se_s = _mean_se(direct[:, c] + late[:, c])
        assert abs(m_w - m_s) < 4 * np.hypot(se_w, se_s) + 1e-9, (c, m_w, se_w, m_s, se_s)
    m_pl, se_pl = _mean_se(late.sum(axis=1))
    m_bl, se_bl = _mean_se(bdpt_late.sum(axis=1))
    assert abs(m_pl - m_bl) < 4 * np.hypot(se_pl, se_bl), (m_pl, se_pl, m_bl, se_bl)
    assert m_pl > 4 * se_pl, (m_pl, se_pl)
