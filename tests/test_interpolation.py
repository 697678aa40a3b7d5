"""The gather's screen-space interpolation (:mod:`ercuts_core.integrators.ercuts.interpolation`):
which points are interpolated, from which anchors, and that the fill reproduces light that
is a reflectance times a linear function exactly (bilinear interpolation's invariant)."""
from __future__ import annotations

import numpy as np
import pytest

from ercuts_core.bsdf import Bsdf
from ercuts_core.integrators.ercuts.interpolation import (MIN_WEIGHT, auto_spacing, grid_offset,
                                                          plan_interpolation)
from ercuts_core.integrators.ercuts.vpl import GBuffer
from ercuts_core.sampling import luminance


class PlaneScene:
    """Shading for a synthetic G-buffer: a textured Principled material per key (base colour
    varying with position, specular 0 so that a dielectric's reflectance is exactly the base
    colour), with the roughness ``rough[key]`` and metallic ``metal[key]``."""

    def __init__(self, rough=(1.0,), metal=None):
        self.rough = np.asarray(rough, float)
        self.metal = np.zeros(len(self.rough)) if metal is None else np.asarray(metal, float)

    @staticmethod
    def base(p):
        t = p[:, 0] * 0.37 + p[:, 1] * 0.61
        return np.stack([0.2 + 0.6 * (t % 1.0), 0.5 + 0.3 * np.sin(t), np.full(len(p), 0.4)], axis=1)

    def bsdf(self, mat, ns, ng, p):
        return Bsdf.from_params(self.base(p), self.rough[mat], self.metal[mat], 0.0, ns, ng)

    def roughness(self, mat, p):
        return self.rough[mat]


def plane_gbuffer(w: int, h: int, depth=None, mat=None, seed: int = 0) -> GBuffer:
    """A w×h G-buffer (one point per pixel) of planes z = depth(x) facing the camera, the
    points jittered in their pixels (pixel pitch 0.1)."""
    rng = np.random.default_rng(seed)
    pix = np.arange(w * h)
    x, y = pix % w + rng.random(w * h), pix // w + rng.random(w * h)
    z = np.zeros(w * h) if depth is None else depth(pix % w)
    p = np.stack([0.1 * x, 0.1 * y, z], axis=1)
    n = np.tile([0.0, 0.0, 1.0], (w * h, 1))
    return GBuffer(pixel=pix, p=p, ng=n, ns=n.copy(), wo=n.copy(),
                   mat=np.zeros(w * h, np.int64) if mat is None else mat,
                   valid=np.ones(w * h, bool), surf=None, samples=1)


def test_a_smooth_plane_gathers_one_pixel_in_four() -> None:
    """On one plane of one material with an odd-sized window every non-anchor point is
    interpolated from the grid corners around it, with bilinear weights."""
    w, h, k = 9, 7, 2
    g = plane_gbuffer(w, h)
    it = plan_interpolation(g, PlaneScene(), w, h, k, (0, 0))
    x, y = np.arange(w * h) % w, np.arange(w * h) // w
    anchors = (x % 2 == 0) & (y % 2 == 0)
    assert np.array_equal(np.sort(it.target), np.flatnonzero(~anchors))
    assert np.array_equal(it.gathered(g.valid), anchors)
    np.testing.assert_allclose(it.weight.sum(axis=1), 1.0, rtol=1e-6)
    used = it.weight > 0
    assert anchors[it.anchor[used]].all()
    # a point between two anchors of a row: 1/2 each; in the middle of four: 1/4 each
    t = list(it.target).index(1)
    assert sorted(it.anchor[t][used[t]]) == [0, 2] and np.allclose(it.weight[t][used[t]], 0.5)
    t = list(it.target).index(w + 1)
    assert sorted(it.anchor[t][used[t]]) == [0, 2, 2 * w, 2 * w + 2]
    assert np.allclose(it.weight[t][used[t]], 0.25)


@pytest.mark.parametrize("offset", [(0, 0), (1, 0), (1, 1)])
def test_the_fill_is_exact_for_reflectance_times_a_linear_function(offset) -> None:
    """Light L = ρ(x)·E(x) with E linear in the position and ρ a texture: the fill
    Σ w_a (ρ(x)/ρ(a)) L(a) equals L at every target whose corners are all inside (bilinear
    weights reproduce linear functions; the ratio restores the texture)."""
    w, h = 9, 7
    g = plane_gbuffer(w, h, seed=3)
    scene = PlaneScene()
    it = plan_interpolation(g, scene, w, h, 2, offset)
    rho = scene.base(g.p)
    px = np.stack([g.pixel % w, g.pixel // w], axis=1).astype(float)    # the grid position
    E = np.stack([1.0 + 0.3 * px[:, 0] - 0.1 * px[:, 1], 2.0 + 0.05 * px[:, 1], 0.5 + 0.02 * px[:, 0]], axis=1)
    truth = np.stack([rho * E, 2.0 * rho * E])             # (2, Q, 3): both light parts
    L = truth.copy()
    L[:, it.target] = -7.0                                 # must be overwritten
    done = it.fill(L, it.gathered(g.valid))
    assert done.all()
    full = np.isclose(it.weight.sum(axis=1), 1.0) & (np.count_nonzero(it.weight, axis=1) ==
                                                     _corners_inside(it.target, w, h, offset))
    np.testing.assert_allclose(L[:, it.target[full]], truth[:, it.target[full]], rtol=1e-5)
    assert full.mean() > 0.3          # the rest extrapolates at the window's border
    assert np.all(L[:, it.target] > 0)


def _corners_inside(target, w, h, offset, k=2):
    """(T,) the number of grid corners with a non-zero bilinear weight, or −1 where one of
    them lies outside the window (the fill extrapolates there)."""
    x, y = target % w, target // w
    dx, dy = (x - offset[0]) % k, (y - offset[1]) % k
    n, outside = np.zeros(len(target), int), np.zeros(len(target), bool)
    for ox, oy in ((0, 0), (k, 0), (0, k), (k, k)):
        wx = np.where(ox == 0, k - dx, dx)
        wy = np.where(oy == 0, k - dy, dy)
        cx, cy = x - dx + ox, y - dy + oy
        pos = (wx > 0) & (wy > 0)
        n += pos
        outside |= pos & ((cx < 0) | (cx >= w) | (cy < 0) | (cy >= h))
    return np.where(outside, -1, n)


def supersampled_gbuffer(w: int, h: int, S: int, step_x: float, seed: int = 0) -> GBuffer:
    """A w×h G-buffer of S points per pixel (entry q = pixel·S + s) jittered in their pixels,
    on the plane z = 0 left of raster x = ``step_x`` and z = 1 right of it (pitch 0.1)."""
    rng = np.random.default_rng(seed)
    pix = np.repeat(np.arange(w * h), S)
    x, y = pix % w + rng.random(len(pix)), pix // w + rng.random(len(pix))
    p = np.stack([0.1 * x, 0.1 * y, np.where(x >= step_x, 1.0, 0.0)], axis=1)
    n = np.tile([0.0, 0.0, 1.0], (len(pix), 1))
    return GBuffer(pixel=pix, p=p, ng=n, ns=n.copy(), wo=n.copy(), mat=np.zeros(len(pix), np.int64),
                   valid=np.ones(len(pix), bool), surf=None, samples=S)


def test_supersampled_points_take_the_light_of_their_pixels_first_point() -> None:
    """S = 4 points per pixel, no spacing (k = 1): every pixel's first point is gathered, and
    the other points on its surface are interpolated from it alone (weight 1) — the pixel
    is anti-aliased at the cost of one gather; points across a depth step inside a pixel
    from their pixel's first point are gathered themselves (edge pixels get S gathers)."""
    w, h, S = 9, 7, 4
    g = supersampled_gbuffer(w, h, S, step_x=4.5)
    it = plan_interpolation(g, PlaneScene(), w, h, 1, (0, 0))
    q = np.arange(w * h * S)
    first = q - q % S
    assert np.all(it.target % S != 0)
    used = it.weight > 0
    assert np.all(used.sum(axis=1) == 1)
    np.testing.assert_array_equal(it.anchor[used], first[it.target])
    same = g.p[:, 2] == g.p[first, 2]
    np.testing.assert_array_equal(np.sort(it.target), np.flatnonzero((q % S != 0) & same))
    gathered = it.gathered(g.valid)
    assert gathered[first].all() and (~same).sum() > 0 and gathered[~same].all()
    # per pixel: one gather where the pixel lies on one surface, S on column 4 (the step)
    per_pixel = np.bincount(g.pixel, weights=gathered.astype(float), minlength=w * h)
    col = np.arange(w * h) % w
    assert np.all(per_pixel[col != 4] == 1) and per_pixel[col == 4].mean() > 1
    # the fill: light ρ(x)·E with E constant per surface is reproduced exactly
    scene = PlaneScene()
    E = np.where(g.p[:, 2:] > 0, [0.5, 1.0, 2.0], [2.0, 1.0, 0.25])
    truth = np.stack([scene.base(g.p) * E])
    L = truth.copy()
    L[:, it.target] = -1.0
    assert it.fill(L, gathered).all()
    np.testing.assert_allclose(L, truth, rtol=1e-5)


def test_a_depth_step_and_another_material_are_not_interpolated_across() -> None:
    """Two parallel planes (a step in depth at column 4) and a second material on rows ≥ 4:
    no target uses an anchor on the other plane or the other material; targets whose
    usable corners are too few (weights < MIN_WEIGHT) are gathered themselves."""
    w, h = 9, 9
    mat = (np.arange(w * h) // w >= 4).astype(np.int64)
    g = plane_gbuffer(w, h, depth=lambda x: np.where(x >= 4, 1.0, 0.0), mat=mat)
    it = plan_interpolation(g, PlaneScene(rough=(1.0, 1.0)), w, h, 2, (0, 0))
    side = (g.pixel % w >= 4).astype(int) * 2 + mat
    used = it.weight > 0
    assert np.all(side[it.anchor][used] == np.repeat(side[it.target][:, None], 4, axis=1)[used])
    # column 3 (between anchors at 2 and 4) has only its left corners: weight 1/2 ≥ MIN_WEIGHT
    assert MIN_WEIGHT <= 0.5
    assert 3 in it.target
    # and without the interpolation's similarity test the step would have been crossed
    flat = plan_interpolation(plane_gbuffer(w, h), PlaneScene(), w, h, 2, (0, 0))
    t = list(flat.target).index(3)
    assert 4 in flat.anchor[t][flat.weight[t] > 0]


def test_glossy_points_and_what_mirrors_show_are_gathered() -> None:
    """Points with a sharp specular lobe (a metal of roughness < ROUGH) and points reached
    through a mirror are never targets, nor anchors of a target; a rough metal is."""
    w, h = 9, 7
    mat = (np.arange(w * h) % w >= 5).astype(np.int64)       # columns 5…8 glossy
    g = plane_gbuffer(w, h, mat=mat)
    g.through = np.zeros(w * h, bool)
    g.through[:w] = True                                      # the top row: seen in a mirror
    it = plan_interpolation(g, PlaneScene(rough=(1.0, 0.1), metal=(0.0, 1.0)), w, h, 2, (0, 0))
    bad = (mat == 1) | g.through
    assert not bad[it.target].any()
    assert not bad[it.anchor][it.weight > 0].any()
    assert len(it.target) > 0
    rough = plan_interpolation(g, PlaneScene(rough=(1.0, 0.6), metal=(0.0, 1.0)), w, h, 2, (0, 0))
    assert (mat[rough.target] == 1).any() and not g.through[rough.target].any()


def test_a_target_waits_for_all_its_anchors() -> None:
    """Before its anchors are gathered a target is not done and carries no light."""
    w, h = 9, 7
    g = plane_gbuffer(w, h)
    it = plan_interpolation(g, PlaneScene(), w, h, 2, (0, 0))
    done = it.gathered(g.valid)
    done[0] = False                                          # one anchor missing
    L = np.ones((2, w * h, 3))
    ok = it.fill(L, done)
    waits = ((it.anchor == 0) & (it.weight > 0)).any(axis=1)
    assert np.array_equal(~ok, waits) and waits.sum() == 3     # pixels 1, w, w + 1
    assert np.all(L[:, it.target[waits]] == 0)


def test_spacing_and_grid_offsets() -> None:
    assert auto_spacing(160 * 120) == 1 and auto_spacing(640 * 480) == 1
    assert auto_spacing(1280 * 720) == 2 and auto_spacing(1920 * 1080) == 2
    assert sorted(grid_offset(2, i) for i in range(4)) == [(0, 0), (0, 1), (1, 0), (1, 1)]
    assert grid_offset(2, 4) == grid_offset(2, 0)
    assert plan_interpolation(plane_gbuffer(4, 4), PlaneScene(), 4, 4, 1, (0, 0)) is None   # S = 1


def test_interpolated_gather_in_a_render_agrees_with_the_full_gather() -> None:
    """``gather_spacing = 2`` through ``render`` on the Cornell box (one shading point per
    pixel): about three quarters
    of the points are interpolated away from its edges, and the indirect light per pixel
    differs from the full gather's (same seed: same VPLs) by noise and a small blur only —
    the mean over the pixels within 4.5 standard errors of the difference, plus 1 %."""
    from ercuts_core import RenderSettings, render, scenes
    desc = scenes.cornell_box(64, 48)
    out = {}
    for k in (1, 2):
        res = render(desc, RenderSettings(gather_spacing=k, shading_samples=1, seed=3, samples=4,
                                          direct_samples=4))
        out[k] = (luminance(res.aovs["indirect"].reshape(-1, 3)), res.stats)
    assert 0.5 < out[2][1]["gather_interpolated"] <= 0.75 and out[1][1]["gather_interpolated"] == 0
    d = out[2][0] - out[1][0]
    assert np.abs(d.mean()) <= 4.5 * d.std(ddof=1) / np.sqrt(d.size) + 0.01 * out[1][0].mean()
    assert np.all(np.isfinite(out[2][0]))
    assert ((out[2][0] > 0) == (out[1][0] > 0)).mean() > 0.99      # no hole, no light outside


def test_supersampled_gather_in_a_render_agrees_with_one_point_per_pixel() -> None:
    """``shading_samples = 4`` through ``render`` on the Cornell box: about three points in
    four are interpolated from their pixels' first points, and the indirect light per pixel
    agrees with one gathered point per pixel (other seeds: the difference is noise) — the
    mean over the pixels within 4.5 standard errors of the difference, plus 1 %."""
    from ercuts_core import RenderSettings, render, scenes
    desc = scenes.cornell_box(64, 48)
    out = {}
    for S in (1, 4):
        res = render(desc, RenderSettings(shading_samples=S, seed=3, samples=4, direct_samples=4))
        out[S] = (luminance(res.aovs["indirect"].reshape(-1, 3)), res.stats)
    assert 0.6 < out[4][1]["gather_interpolated"] <= 0.75 and out[1][1]["gather_interpolated"] == 0
    d = out[4][0] - out[1][0]
    assert np.abs(d.mean()) <= 4.5 * d.std(ddof=1) / np.sqrt(d.size) + 0.01 * out[1][0].mean()
    assert np.all(np.isfinite(out[4][0]))
    one, four = (out[S][0].reshape(48, 64) > 0 for S in (1, 4))
    assert (one & ~four).mean() < 0.01                               # no hole
    # light where one point per pixel saw none only on the room's outline: pixels that
    # the room covers partly (the anti-aliasing), next to a pixel lit with one point
    near = np.zeros_like(one)
    near[1:] |= one[:-1]; near[:-1] |= one[1:]; near[:, 1:] |= one[:, :-1]; near[:, :-1] |= one[:, 1:]
    assert (four & ~one).any() and np.all(near[four & ~one])


def test_planning_polls_and_stops_when_asked() -> None:
    """``keep_going`` is called during the planning (progress, Esc); False stops it (None:
    the caller gathers every point, or nothing once cancelled)."""
    w, h = 9, 7
    calls = []
    it = plan_interpolation(plane_gbuffer(w, h), PlaneScene(), w, h, 2, (0, 0),
                            keep_going=lambda: calls.append(1) or True)
    assert it is not None and len(calls) >= 5           # a chunk, then the four corners
    assert plan_interpolation(plane_gbuffer(w, h), PlaneScene(), w, h, 2, (0, 0),
                              keep_going=lambda: False) is None


def test_previews_during_an_interpolated_gather_have_no_holes() -> None:
    """The previews sent while an interpolated gather runs show the interpolated points
    filled (or the rough image where their anchors are not gathered yet): after the first
    one (the rough BDPT image's first pass, 9 % of its pixels still unsampled, as without
    interpolation) no preview has more than 1 % black pixels where the final image is lit."""
    from ercuts_core import RenderSettings, render, scenes
    images = []
    res = render(scenes.cornell_box(64, 48), RenderSettings(gather_spacing=2, seed=5, samples=4, direct_samples=4),
                 preview=lambda img: images.append(np.array(img, copy=True)))
    assert res.stats["gather_interpolated"] > 0.5 and len(images) >= 2
    lit = luminance(res.image[..., :3]) > 0
    for img in images[1:]:
        assert np.all(np.isfinite(img))
        assert (luminance(img[..., :3])[lit] > 0).mean() > 0.99
