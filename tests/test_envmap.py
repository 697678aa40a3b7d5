"""HDRI environment light (``ercuts_core.envmap``, ``SceneDescription.world_map``): Cycles'
equirectangular orientation, bilinear lookup, sampling ↔ pdf consistency (chi², pdf
integrates to 1), the light's power, validation and the npz round trip, and renders: a
constant map equals the constant world, PATH/BDPT/ERCUTS agree, light comes from the
bright side."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import chisquare

from ercuts_core import RenderSettings, SunLights, load_npz, render, save_npz
from ercuts_core.description import CameraDesc, MaterialTable, MeshTable, SceneDescription, WorldMap
from ercuts_core.envmap import EnvMap, direction_to_uv, uv_to_direction
from ercuts_core.lights import ENV
from ercuts_core.sampling import luminance, sample_uniform_sphere
from ercuts_core.scene import BuiltScene
from ercuts_core.scenes import icosphere, look_at
from ercuts_core.validate import sanitize
from test_bdpt import _assert_agree, _renders, sun_sky_scene

RNG = np.random.default_rng(2024)


def _rot_z(deg: float) -> np.ndarray:
    c, s = np.cos(np.radians(deg)), np.sin(np.radians(deg))
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def _rot_x(deg: float) -> np.ndarray:
    c, s = np.cos(np.radians(deg)), np.sin(np.radians(deg))
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])


def _busy_map(H: int = 16, W: int = 32) -> np.ndarray:
    """A random map with a hot spot, black texels and a bright texel next to the pole."""
    rng = np.random.default_rng(5)
    L = (rng.random((H, W, 3)) ** 4).astype(np.float32)
    L[rng.random((H, W)) < 0.2] = 0.0
    L[3:5, 10:12] = (40.0, 30.0, 20.0)
    L[H - 1, 7] = (5.0, 5.0, 5.0)
    return L


def _sky_scene(world_map: WorldMap | None, width: int = 24, height: int = 18):
    """The open sun/sky scene of test_bdpt without its sun, lit by the world alone."""
    d = sun_sky_scene(width, height)
    return d.replace(world_map=world_map, sun_lights=SunLights(np.zeros((0, 3)), np.zeros((0, 3)), [], []))


def zup_scene(world_map: WorldMap | None, width: int = 48, height: int = 36) -> SceneDescription:
    """Blender's frame (+Z up): a grey ground at z = 0 and a smooth sphere (r 0.6) on it, seen
    from −Y (Blender's front view), so +X is the image's right."""
    g = 4.0
    ground = np.array([(-g, -g, 0), (g, -g, 0), (g, g, 0), (-g, g, 0)], float)
    sv, sf = icosphere(3)
    pos = np.vstack([ground, sv * 0.6 + [0, 0, 0.6]])
    tris = np.vstack([[[0, 1, 2], [0, 2, 3]], sf + 4])
    ids = np.r_[0, 0, np.ones(len(sf), int)]
    mesh = MeshTable(pos, tris, ids, ids, normals=np.vstack([np.tile([0, 0, 1.0], (4, 1)), sv]),
                     smooth=np.r_[False, False, np.ones(len(sf), bool)])
    mats = MaterialTable.diffuse(["Ground", "Ball"], [[0.5, 0.5, 0.5], [0.8, 0.8, 0.8]])
    cam = CameraDesc(look_at((0.0, -4.0, 1.2), (0.0, 0.0, 0.5), up=(0, 0, 1)), width, height, lens=35.0)
    return SceneDescription(mesh, mats, cam, world_map=world_map, object_names=("Ground", "Ball"))


# --------------------------------------------------------------------------- convention
def test_equirect_convention_is_cycles():
    """u = 0.5 − atan2(y, x)/2π, v = 0.5 + elevation/π (Cycles direction_to_equirectangular)."""
    d = np.array([[1.0, 0, 0], [0, 1, 0], [-1, 0, 1e-9], [0, -1, 0], [0, 0, 1], [0, 0, -1]])
    u, v = direction_to_uv(d)
    np.testing.assert_allclose(u[:4], [0.5, 0.25, 0.0, 0.75], atol=1e-9)
    np.testing.assert_allclose(v, [0.5, 0.5, 0.5, 0.5, 1.0, 0.0], atol=1e-9)
    uv = RNG.random((1000, 2))
    back = direction_to_uv(uv_to_direction(uv[:, 0], uv[:, 1]))
    np.testing.assert_allclose(np.stack(back, 1), uv, atol=1e-12)


def test_lookup_hits_texel_centres_and_row_zero_is_the_nadir():
    H, W = 8, 16
    L = np.zeros((H, W, 3), np.float32)
    L[6, 3] = (1, 2, 3)                               # upper half: row 0 is the bottom
    m = EnvMap(L)
    d = uv_to_direction(np.array([(3 + 0.5) / W]), np.array([(6 + 0.5) / H]))
    np.testing.assert_allclose(m.lookup(d)[0], [1, 2, 3], rtol=1e-6)
    assert d[0, 2] > 0                                # that texel is above the horizon
    # Half-way between two texel centres: the mean (bilinear), and wrap across u = 0
    d = uv_to_direction(np.array([4.0 / W]), np.array([(6 + 0.5) / H]))
    np.testing.assert_allclose(m.lookup(d)[0], [0.5, 1, 1.5], rtol=1e-6)
    L2 = np.zeros((H, W, 3), np.float32)
    L2[2, 0], L2[2, W - 1] = 1.0, 3.0
    d = uv_to_direction(np.array([0.0]), np.array([(2 + 0.5) / H]))
    np.testing.assert_allclose(EnvMap(L2).lookup(d)[0], [2, 2, 2], rtol=1e-6)


def test_rotation_maps_world_directions_to_map_space():
    L = _busy_map()
    R = _rot_z(90.0)
    d = sample_uniform_sphere(RNG.random((100, 2)))
    np.testing.assert_allclose(EnvMap(L, R).lookup(d), EnvMap(L).lookup(d @ R.T), rtol=1e-12)


# --------------------------------------------------------------------------- sampling
@pytest.mark.parametrize("rotation", [None, _rot_x(30.0) @ _rot_z(70.0)])
def test_sample_pdf_agree_and_pdf_integrates_to_one(rotation):
    m = EnvMap(_busy_map(), rotation)
    d, pdf = m.sample(RNG.random((50_000, 2)))
    assert np.allclose(np.linalg.norm(d, axis=1), 1.0)
    np.testing.assert_allclose(m.pdf(d), pdf, rtol=1e-6)
    # ∫ pdf dω = Σ pdf(u, v)·2π² sinθ ΔuΔv on a fine midpoint grid (8 points per cell side)
    n_u, n_v = 32 * 8, 16 * 8
    u, v = np.meshgrid((np.arange(n_u) + 0.5) / n_u, (np.arange(n_v) + 0.5) / n_v)
    dm = uv_to_direction(u.ravel(), v.ravel())
    sin_t = np.cos(np.pi * (v.ravel() - 0.5))
    total = (m.pdf(m.to_world(dm)) * 2 * np.pi**2 * sin_t).sum() / (n_u * n_v)
    assert abs(total - 1.0) < 1e-6                     # exact but for the float32 cell table
    # The pdf is positive wherever the looked-up radiance is (no zero-pdf light)
    L = m.lookup(m.to_world(dm))
    assert (m.pdf(m.to_world(dm))[luminance(L) > 0] > 0).all()


def test_sampling_chi_square():
    """Histogram of 200k samples over 16 × 8 (u, v) bins in map space vs the pdf's integrals."""
    m = EnvMap(_busy_map(), _rot_z(40.0))
    n = 200_000
    d, _ = m.sample(RNG.random((n, 2)))
    u, v = direction_to_uv(m.to_map(d))
    bu, bv = 16, 8
    cell = np.minimum((v * bv).astype(int), bv - 1) * bu + np.minimum((u * bu).astype(int), bu - 1)
    obs = np.bincount(cell, minlength=bu * bv)
    k = 16                                               # midpoint points per bin side
    uu, vv = np.meshgrid((np.arange(bu * k) + 0.5) / (bu * k), (np.arange(bv * k) + 0.5) / (bv * k))
    dm = uv_to_direction(uu.ravel(), vv.ravel())
    w = m.pdf(m.to_world(dm)) * 2 * np.pi**2 * np.cos(np.pi * (vv.ravel() - 0.5)) / (bu * bv * k * k)
    expect = w.reshape(bv, k, bu, k).sum(axis=(1, 3)).ravel() * n
    keep = expect > 5
    assert obs[~keep].sum() < 20
    _, p = chisquare(obs[keep], expect[keep] * obs[keep].sum() / expect[keep].sum())
    assert p > 0.001, p


def test_black_map_has_no_light():
    m = EnvMap(np.zeros((4, 8, 3), np.float32))
    d, pdf = m.sample(RNG.random((10, 2)))
    assert (pdf == 0).all() and (m.pdf(d) == 0).all() and m.integral_Y == 0


# --------------------------------------------------------------------------- the light
def _lights(world_map):
    return BuiltScene(sanitize(_sky_scene(world_map)).desc).lights


def test_env_light_power_illuminate_and_emit_densities_are_consistent():
    L = _busy_map()
    ls = _lights(WorldMap(L, _rot_z(25.0)))
    assert ls.env_light >= 0 and ls.kind[ls.env_light] == ENV
    # ∫ Y(L) dω by uniform sampling vs the map's integral (the selection power / πR²)
    w = sample_uniform_sphere(RNG.random((400_000, 2)))
    mc = luminance(ls.env_radiance(w)).mean() * 4 * np.pi
    assert abs(ls.env_map.integral_Y / mc - 1) < 0.02
    n = 20_000
    x = np.zeros((n, 3))
    s = ls.illuminate(x, RNG.random(n), RNG.random((n, 2)))
    np.testing.assert_allclose(s.pdf_w, ls.pdf_illuminate_env(s.wi), rtol=1e-6)
    np.testing.assert_allclose(s.Li, ls.env_radiance(s.wi))
    # Unbiased irradiance-like estimate: E[Y(Li)/pdf] = ∫ Y dω
    est = (luminance(s.Li) / s.pdf_w).mean()
    assert abs(est / ls.env_map.integral_Y - 1) < 0.05
    e = ls.emit(RNG.random(n), RNG.random((n, 2)), RNG.random((n, 2)))
    pdf_pos, pdf_dir = ls.pdf_emit(e.light, e.p, e.n, e.d)
    np.testing.assert_allclose(pdf_pos, e.pdf_pos)
    np.testing.assert_allclose(pdf_dir, e.pdf_dir, rtol=1e-6)
    np.testing.assert_allclose(e.Le, ls.env_radiance(-e.d))
    # Emitted power: E[Y(β)] = πR²·∫Y dω (the light's selection power)
    power = np.pi * ls.radius**2 * ls.env_map.integral_Y
    assert abs(luminance(e.beta).mean() / power - 1) < 0.05


def test_constant_map_power_matches_constant_world():
    c = np.array([0.3, 0.4, 0.6])
    ls_const = BuiltScene(sanitize(_sky_scene(None).replace(world_radiance=c)).desc).lights
    ls_map = _lights(WorldMap(np.tile(c.astype(np.float32), (16, 32, 1))))
    p_c, p_m = ls_const.distribution.total, ls_map.distribution.total
    assert abs(p_m / p_c - 1) < 1e-3
    np.testing.assert_allclose(ls_map.env_radiance(sample_uniform_sphere(RNG.random((50, 2)))),
                               np.tile(c, (50, 1)), rtol=1e-6)


# --------------------------------------------------------------------------- description
def test_npz_round_trip(tmp_path):
    wm = WorldMap(_busy_map(), _rot_z(30.0))
    d = _sky_scene(wm)
    save_npz(d, tmp_path / "env.npz")
    back = load_npz(tmp_path / "env.npz")
    np.testing.assert_array_equal(back.world_map.radiance, wm.radiance)
    np.testing.assert_array_equal(back.world_map.rotation, wm.rotation)
    assert back.world_map.radiance.dtype == np.float32
    save_npz(_sky_scene(None), tmp_path / "plain.npz")
    assert load_npz(tmp_path / "plain.npz").world_map is None


def test_bad_texels_warn_and_are_black():
    L = _busy_map()
    L[0, 0, 0], L[1, 1, 1], L[2, 2] = np.nan, np.inf, -1.0
    v = sanitize(_sky_scene(WorldMap(L)))
    assert [i.code for i in v.issues] == ["bad_world_map"]
    assert "3 environment texels" in v.issues[0].message
    r = v.desc.world_map.radiance
    assert np.isfinite(r).all() and (r >= 0).all() and r[0, 0, 0] == 0 and r[2, 2].max() == 0


def test_empty_map_falls_back_to_the_constant_world():
    d = _sky_scene(WorldMap(np.zeros((0, 0, 3)))).replace(world_radiance=[0.1, 0.2, 0.3])
    v = sanitize(d)
    assert [i.code for i in v.issues] == ["empty_world_map"] and v.desc.world_map is None
    np.testing.assert_allclose(v.desc.world_radiance, [0.1, 0.2, 0.3])


def test_non_rotation_is_replaced_by_the_nearest_rotation():
    v = sanitize(_sky_scene(WorldMap(_busy_map(), 2.0 * _rot_z(30.0))))
    assert [i.code for i in v.issues] == ["bad_world_rotation"]
    np.testing.assert_allclose(v.desc.world_map.rotation, _rot_z(30.0), atol=1e-6)


# --------------------------------------------------------------------------- renders
def _hot_map(H: int = 32, W: int = 64) -> np.ndarray:
    """Dim sky, a bright patch around +X (u ≈ 0.5), 30° above the horizon."""
    L = np.full((H, W, 3), 0.2, np.float32)
    i = int((0.5 + 30 / 180) * H)
    L[i - 2:i + 2, W // 2 - 3:W // 2 + 3] = (30.0, 25.0, 20.0)
    return L


def test_constant_map_renders_like_the_constant_world():
    """PATH and BDPT with a constant map vs the constant world_radiance (statistical)."""
    c = np.array([0.3, 0.4, 0.6], np.float32)
    const = _sky_scene(None).replace(world_radiance=c)
    cmap = _sky_scene(WorldMap(np.tile(c, (16, 32, 1))))
    for integrator, spp in (("PATH", 16), ("BDPT", 8)):
        a = _renders(const, integrator, 6, spp, seed0=100)
        b = _renders(cmap, integrator, 6, spp, seed0=200)
        _assert_agree(a, b)
    # ERCUTS: the same image energy (chains and VPLs see the map as they see the constant)
    fast = dict(integrator="ERCUTS", rough_samples=8, chain_length=40, chains_per_pixel=0.5, seed=1)
    e_c = luminance(render(const, RenderSettings(**fast)).image[..., :3]).mean()
    e_m = luminance(render(cmap, RenderSettings(**fast)).image[..., :3]).mean()
    assert abs(e_m / e_c - 1) < 0.03, (e_m, e_c)


def test_hot_spot_map_path_bdpt_ercuts_agree():
    d = _sky_scene(WorldMap(_hot_map()))
    path = _renders(d, "PATH", 6, 32, seed0=1000)
    bdpt = _renders(d, "BDPT", 6, 16, seed0=2000)
    _assert_agree(path, bdpt)
    fast = dict(integrator="ERCUTS", rough_samples=8, chain_length=40, chains_per_pixel=0.5, seed=3)
    e = render(d, RenderSettings(**fast)).image[..., :3]
    ref = path.mean(0)
    assert abs(luminance(e).mean() / luminance(ref).mean() - 1) < 0.03
    # Mean absolute pixel error of one 8-sample ERCUTS render at 24×18 (measured 0.082;
    # the same render of the constant sky: ~0.07): noise, not bias
    assert np.abs(e - ref).mean() / ref.mean() < 0.12


def test_light_comes_from_the_bright_side():
    """A hot spot toward +X (map space, 30° up) lights the sphere's +X side (the image's right
    in Blender's front view) and casts its shadow toward −X; rotating the map by 180° about Z
    (a Mapping node) mirrors that."""
    settings = RenderSettings(integrator="PATH", samples=16, seed=4)
    img = render(zup_scene(WorldMap(_hot_map())), settings).image[..., :3]
    turned = render(zup_scene(WorldMap(_hot_map(), _rot_z(180.0))), settings).image[..., :3]
    h, w = img.shape[:2]
    ball = slice(h // 4, h // 2)                       # rows through the sphere's upper half
    lum, lum_t = luminance(img[ball]), luminance(turned[ball])
    left, right = slice(w // 2 - 8, w // 2 - 1), slice(w // 2 + 1, w // 2 + 8)
    assert lum[:, right].mean() > 2.0 * lum[:, left].mean()
    assert lum_t[:, left].mean() > 2.0 * lum_t[:, right].mean()
    # The rotation mirrors the image (the scene is symmetric under x → −x)
    np.testing.assert_allclose(luminance(img).mean(), luminance(turned).mean(), rtol=0.05)
