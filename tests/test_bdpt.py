"""Bidirectional path tracer: analytic furnace, agreement with the path tracer (the oracle),
per-strategy images, determinism and the non-finite counter.

The cross-integrator tests follow the Mitsuba ``test_renders.py`` recipe (style-and-testing
§2.8): per-pixel, per-channel tests of the BDPT mean against the PATH mean with variances
estimated from K independent renders of each, at a Šidák-corrected family level of 1 %; at
least 99 % of the tests must pass (a few pixels see heavy-tailed PATH estimates, e.g. the
1 cm gap above the Cornell lamp), and the image means must agree within 3σ. With variances
estimated from K ≈ 10 renders the Z statistic follows Student's t, so p-values use the
Welch–Satterthwaite degrees of freedom (with K = 6 a plain normal reference fails ~3 % of
the pixels of a perfectly unbiased furnace).
"""
from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import t as student_t

from ercuts_core import RenderSettings, render
from ercuts_core.description import CameraDesc, MaterialTable, MeshTable, SceneDescription, SunLights
from ercuts_core.film import Film
from ercuts_core.integrators.bdpt import BDPTIntegrator
from ercuts_core.scene import BuiltScene
from ercuts_core.scenes import cornell_box, furnace, icosphere, look_at, point_lit_box
from ercuts_core.validate import sanitize


# --------------------------------------------------------------------------- scenes
def glossy_cornell(width: int = 24, height: int = 18) -> SceneDescription:
    """Cornell box (mesh lamp) whose tall box is glossy (roughness 0.3, specular 0.5) and
    whose short box is a rough metal (roughness 0.3, metallic 1)."""
    d = cornell_box(width, height, "mesh")
    m = d.materials
    mats = MaterialTable(
        m.names + ("Glossy", "Metal"),
        np.vstack([m.base_color, [[0.7, 0.7, 0.7], [0.9, 0.6, 0.3]]]),
        np.append(m.roughness, [0.3, 0.3]), np.append(m.metallic, [0.0, 1.0]),
        np.append(m.specular, [0.5, 0.5]), np.vstack([m.emission, np.zeros((2, 3))]))
    names = list(d.object_names)
    mat_ids = d.mesh.material_ids.copy()
    mat_ids[d.mesh.object_ids == names.index("TallBox")] = m.n_materials
    mat_ids[d.mesh.object_ids == names.index("ShortBox")] = m.n_materials + 1
    mesh = MeshTable(d.mesh.positions, d.mesh.triangles, mat_ids, d.mesh.object_ids)
    return d.replace(mesh=mesh, materials=mats)


def _mirrored_sphere(center, radius, level=1):
    """Smooth icosphere under the negative-scale transform diag(−r, r, r) + center, exported
    as Blender would: positions transformed, winding reversed (det < 0), normals by the
    inverse transpose."""
    v, f = icosphere(level)
    scale = np.array([-radius, radius, radius])
    pos = v * scale + np.asarray(center, float)
    nrm = v / scale
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    return pos, f[:, ::-1].copy(), nrm


def mirrored_scene(width: int = 24, height: int = 18) -> SceneDescription:
    """Closed room lit by a mirrored, smooth-shaded emissive sphere, with a mirrored,
    smooth-shaded receiver sphere (pbrt-v3 #229: negative scale + vertex normals)."""
    room = cornell_box(width, height, "area")                 # walls and boxes, no lamp mesh
    mesh = room.mesh
    pos = [mesh.positions.astype(float)]
    tris = [mesh.triangles]
    nrm = [np.zeros((len(mesh.positions), 3))]
    mats = [mesh.material_ids]
    objs = [mesh.object_ids]
    smooth = [np.zeros(mesh.n_triangles, bool)]
    n_v = len(mesh.positions)
    n_obj = len(room.object_names)
    for i, (c, r, mat) in enumerate([((0.3, 1.55, 0.2), 0.15, 3), ((-0.45, 1.5, 0.3), 0.3, 0)]):
        p, f, n = _mirrored_sphere(c, r)
        pos.append(p)
        tris.append(f + n_v)
        nrm.append(n)
        mats.append(np.full(len(f), mat))
        objs.append(np.full(len(f), n_obj + i))
        smooth.append(np.ones(len(f), bool))
        n_v += len(p)
    m = room.materials
    emission = m.emission.copy()
    emission[3] = [6.0, 5.0, 4.0]
    mats_t = MaterialTable(m.names, m.base_color, m.roughness, m.metallic, m.specular, emission)
    mesh = MeshTable(np.concatenate(pos), np.concatenate(tris), np.concatenate(mats),
                     np.concatenate(objs), normals=np.concatenate(nrm), smooth=np.concatenate(smooth))
    return SceneDescription(mesh, mats_t, room.camera,
                            object_names=room.object_names + ("MirroredLamp", "MirroredBall"))


def sun_sky_scene(width: int = 24, height: int = 18) -> SceneDescription:
    """Open scene: ground, a block and a glossy smooth sphere under a sun and a constant sky."""
    quads = []
    g = 3.0
    quads.append([(-g, 0, g), (g, 0, g), (g, 0, -g), (-g, 0, -g)])
    lo, hi = (-1.2, 0.0, -0.8), (-0.2, 1.0, 0.2)
    x0, y0, z0 = lo
    x1, y1, z1 = hi
    quads += [[(x0, y0, z0), (x0, y0, z1), (x0, y1, z1), (x0, y1, z0)],
              [(x1, y0, z0), (x1, y1, z0), (x1, y1, z1), (x1, y0, z1)],
              [(x0, y1, z0), (x0, y1, z1), (x1, y1, z1), (x1, y1, z0)],
              [(x0, y0, z0), (x0, y1, z0), (x1, y1, z0), (x1, y0, z0)],
              [(x0, y0, z1), (x1, y0, z1), (x1, y1, z1), (x0, y1, z1)]]
    pos = np.array(quads, float).reshape(-1, 3)
    tris = np.concatenate([np.array([[0, 1, 2], [0, 2, 3]]) + 4 * i for i in range(len(quads))])
    sv, sf = icosphere(2)
    sphere_pos = sv * 0.6 + [0.8, 0.6, 0.0]
    mesh = MeshTable(np.vstack([pos, sphere_pos]), np.vstack([tris, sf + len(pos)]),
                     np.r_[np.zeros(2), np.ones(len(tris) - 2), np.full(len(sf), 2)],
                     np.r_[np.zeros(2), np.ones(len(tris) - 2), np.full(len(sf), 2)],
                     normals=np.vstack([np.zeros_like(pos), sv]),
                     smooth=np.r_[np.zeros(len(tris), bool), np.ones(len(sf), bool)])
    mats = MaterialTable(["Ground", "Block", "Ball"], [[0.6, 0.6, 0.55], [0.8, 0.3, 0.2], [0.3, 0.5, 0.8]],
                         [1.0, 1.0, 0.3], [0.0, 0.0, 0.0], [0.0, 0.0, 0.5], np.zeros((3, 3)))
    sun_dir = np.array([0.4, -1.0, -0.3])
    sun = SunLights([sun_dir / np.linalg.norm(sun_dir)], [[2.0, 1.9, 1.7]], [0.0], [3])
    cam = CameraDesc(look_at((0.5, 2.5, 4.0), (0.0, 0.4, 0.0)), width, height, lens=35.0)
    return SceneDescription(mesh, mats, cam, sun_lights=sun, world_radiance=[0.3, 0.4, 0.6],
                            object_names=("Ground", "Block", "Ball", "Sun"))


def ortho_cornell(width: int = 24, height: int = 18) -> SceneDescription:
    d = cornell_box(width, height, "mesh")
    cam = CameraDesc(look_at((0, 1, 3.9), (0, 1, 0)), width, height, projection="ORTHO",
                     ortho_scale=2.4)
    return d.replace(camera=cam)


# --------------------------------------------------------------------------- helpers
def _renders(desc: SceneDescription, integrator: str, k: int, spp: int, seed0: int = 0,
             **settings) -> np.ndarray:
    """(k, h, w, 3) images of k independent renders; checks the non-finite counter."""
    out = []
    for i in range(k):
        r = render(desc, RenderSettings(integrator=integrator, samples=spp, seed=seed0 + i,
                                        **settings))
        assert r.stats["nonfinite_samples"] == 0
        assert np.isfinite(r.image).all()
        out.append(r.image[..., :3].astype(np.float64))
    return np.array(out)


def _p_values(diff: np.ndarray, va: np.ndarray, ka: int, vb: np.ndarray | float = 0.0,
              kb: int = 2) -> np.ndarray:
    """Two-sided Welch t-test p-values of mean differences ``diff`` with squared standard
    errors va (from ka renders) and vb (from kb renders); equal means with zero variance pass."""
    var = va + vb
    se = np.sqrt(var)
    t = np.divide(np.abs(diff), se, out=np.full(np.shape(diff), np.inf), where=se > 0)
    den = va**2 / (ka - 1) + np.asarray(vb) ** 2 / (kb - 1)
    dof = np.divide(var**2, den, out=np.full(np.shape(diff), 1.0), where=den > 0)
    p = 2.0 * student_t.sf(t, np.maximum(dof, 1.0))
    return np.where(se > 0, p, np.where(np.abs(diff) <= 1e-7, 1.0, 0.0))


def _assert_agree(a: np.ndarray, b: np.ndarray, significance: float = 0.01,
                  min_pass: float = 0.99) -> None:
    """Per-pixel/channel Welch tests (Šidák-corrected) and image means within 3σ."""
    ma, mb = a.mean(0), b.mean(0)
    va, vb = a.var(0, ddof=1) / len(a), b.var(0, ddof=1) / len(b)
    p = _p_values(ma - mb, va, len(a), vb, len(b))
    level = 1.0 - (1.0 - significance) ** (1.0 / p.size)
    passed = (p >= level).mean()
    # Image means: one number per render, so their spread includes pixel correlations. The
    # spread is estimated from the k renders: Welch's t at the level of a normal 3σ test
    # (two-sided 0.27 %), not 3σ itself, which with 6 + 6 renders rejects 1.3 % of equal means.
    ia, ib = a.mean(axis=(1, 2, 3)), b.mean(axis=(1, 2, 3))
    va_img, vb_img = ia.var(ddof=1) / len(ia), ib.var(ddof=1) / len(ib)
    se_img = np.sqrt(va_img + vb_img)
    dof = se_img**4 / max(va_img**2 / (len(ia) - 1) + vb_img**2 / (len(ib) - 1), 1e-300)
    t_crit = student_t.ppf(1.0 - 0.0027 / 2.0, dof)
    msg = (f"pass rate {passed:.4f}, min p {p.min():.2e} (level {level:.1e}); "
           f"means {ia.mean():.5f} vs {ib.mean():.5f} ± {se_img:.5f} (t limit {t_crit:.2f})")
    assert passed >= min_pass, msg
    assert abs(ia.mean() - ib.mean()) <= t_crit * se_img, msg
    assert ia.mean() > 0, msg


def _compare(desc: SceneDescription, k: int = 10, spp_path: int = 32, spp_bdpt: int = 16,
             **settings) -> None:
    path = _renders(desc, "PATH", k, spp_path, seed0=1000, **settings)
    bdpt = _renders(desc, "BDPT", k, spp_bdpt, seed0=2000, **settings)
    _assert_agree(path, bdpt)


def _render_with_strategies(desc: SceneDescription, settings: RenderSettings):
    """Drive the integrator like ercuts_core.render does, keeping the strategy images."""
    scene = BuiltScene(sanitize(desc).desc)
    integ = BDPTIntegrator(scene, settings, debug_strategies=True)
    film = Film(scene.camera.window)
    n = film.window.n_pixels
    for k in range(settings.samples):
        part = Film(film.window)
        integ.render_batch(part, np.arange(n), np.random.default_rng([settings.seed, k, 0]))
        film.merge(part)
    scene.close()
    return film, integ.strategy_images


# --------------------------------------------------------------------------- tests
def test_furnace_every_pixel_is_one():
    """Closed sphere, albedo 0.5, Le 0.5: each pixel's expectation is 1 (pbrt integrators_test).

    max_depth 20 truncates 0.5^21 of the energy; rr_depth 3 exercises Russian roulette on
    both subpaths.
    """
    imgs = _renders(furnace(albedo=0.5, emission=0.5), "BDPT", k=16, spp=8, max_depth=20)
    lum = imgs.mean(axis=3)                                  # grey scene: all channels equal
    means = lum.mean(axis=(1, 2))
    se = means.std(ddof=1) / np.sqrt(len(means))
    assert abs(means.mean() - 1.0) < 0.025
    assert abs(means.mean() - 1.0) < max(4 * se, 1e-3)
    # Per pixel: t-test against 1 with variances across the renders (Šidák, ≥ 99 % pass).
    p = _p_values(lum.mean(0) - 1.0, lum.var(axis=0, ddof=1) / len(lum), len(lum))
    level = 1.0 - 0.99 ** (1.0 / p.size)
    assert (p >= level).mean() >= 0.99


@pytest.mark.parametrize("name, make, kw", [
    ("cornell_mesh", lambda: cornell_box(24, 18, "mesh"), {}),
    ("cornell_area", lambda: cornell_box(24, 18, "area"), {}),
    ("point_lit_box", lambda: point_lit_box(24, 18), {}),
    ("furnace_smooth", lambda: furnace(smooth=True, width=12, height=12), {"max_depth": 12}),
    ("mirrored", lambda: mirrored_scene(24, 18), {}),
    ("glossy", lambda: glossy_cornell(24, 18), {}),
    ("sun_sky", lambda: sun_sky_scene(24, 18), {}),
    ("ortho", lambda: ortho_cornell(24, 18), {}),
])
def test_bdpt_agrees_with_path(name, make, kw):
    """3–8 s each: K = 10 renders per integrator at 24×18 (PATH 32 spp, BDPT 16 spp)."""
    _compare(make(), **kw)


def test_low_depth_agrees_with_path():
    """max_depth 1 and 2 (direct light; one bounce) on the Cornell box with an area light."""
    for depth in (1, 2):
        _compare(cornell_box(16, 12, "area"), k=6, spp_path=32, spp_bdpt=16, max_depth=depth)


def test_strategy_images_sum_to_the_image():
    desc = cornell_box(16, 12, "mesh")
    settings = RenderSettings(integrator="BDPT", samples=4, seed=3, max_depth=5)
    film, images = _render_with_strategies(desc, settings)
    assert film.nonfinite == 0
    full = film.image()[..., :3].reshape(-1, 3).astype(np.float64)
    total = sum(images.values()) / settings.samples
    np.testing.assert_allclose(total, full, rtol=1e-5, atol=1e-6)
    # Every strategy with depth ≤ max_depth (except (1, 1)) contributed, and only those.
    assert (0, 2) in images and (1, 2) in images and (2, 1) in images and (2, 2) in images
    for (s, t), img in images.items():
        assert 0 <= s + t - 2 <= settings.max_depth and (s, t) != (1, 1)
        assert np.isfinite(img).all() and (img >= 0).all(), (s, t)


def test_first_hit_aovs_and_alpha_match_path():
    """Both integrators draw the camera rays first, so the same seed gives the same AOVs."""
    s = RenderSettings(samples=2, seed=1, film_transparent=True)
    desc = sun_sky_scene(16, 12)
    a = render(desc, s.replace(integrator="PATH"))
    b = render(desc, s.replace(integrator="BDPT"))
    np.testing.assert_array_equal(a.image[..., 3], b.image[..., 3])
    assert 0 < b.image[..., 3].mean() < 1
    for name in ("depth", "normal", "albedo"):
        np.testing.assert_allclose(a.aovs[name], b.aovs[name], rtol=1e-6, atol=1e-6)


def test_orthographic_camera_has_no_light_tracing_strategy():
    desc = ortho_cornell(16, 12)
    film, images = _render_with_strategies(desc, RenderSettings(integrator="BDPT", samples=2))
    assert not any(t == 1 for _, t in images) and film.splat.sum() == 0
    assert film.color.sum() > 0 and film.nonfinite == 0


@pytest.mark.parametrize("direct_light", ["NEE", "VPL"])
def test_seed_paths_are_valid_paths_whose_energy_matches_path_tracer_seeds(direct_light):
    """ERCUTS seeding: BDPT seeds are unoccluded target-class paths with f > 0 whose raster
    position is x1's projection, and Σe estimates the same energy as path-traced seeds
    (indirect paths only with direct light by NEE; also x2 on the light with 'VPL')."""
    from ercuts_core.integrators.ercuts.initialization import seeds_from_path_tracer
    from ercuts_core.integrators.ercuts.paths import contribution, edge_visible, is_target
    from ercuts_core.integrators.ercuts.seeding import seed_paths

    scene = BuiltScene(sanitize(cornell_box(16, 12, "mesh")).desc)
    settings = RenderSettings(max_depth=5, direct_light=direct_light)
    direct = direct_light == "VPL"
    paths, e = seed_paths(scene, settings, np.random.default_rng(0))
    assert len(paths) > 0 and paths.slots == settings.max_depth + 2
    assert (e > 0).all() and is_target(scene, paths, direct).all()
    assert (paths.k == 2).any() == direct
    assert (contribution(scene, paths).max(axis=1) > 0).all()
    for i in range(int(paths.k.max())):
        m = paths.k > i
        assert edge_visible(scene, paths.take(m), np.full(int(m.sum()), i)).all()
    raster, inside = scene.camera.raster_of(paths.p[:, 1])
    assert inside.all() and np.abs(raster - paths.raster).max() < 1e-4
    # Σe over one sample per pixel: same expectation as the path tracer's seeds
    eb = np.array([seed_paths(scene, settings, np.random.default_rng(s))[1].sum() for s in range(30)])
    ep = np.array([seeds_from_path_tracer(scene, settings.max_depth, np.random.default_rng(100 + s),
                                          direct=direct)[1].sum() for s in range(30)])
    se = np.sqrt(eb.var(ddof=1) / len(eb) + ep.var(ddof=1) / len(ep))
    assert abs(eb.mean() - ep.mean()) < 4 * se, (eb.mean(), ep.mean(), se)
    scene.close()
