"""Agreement with Cycles, rendered by the same Blender: light units, camera, full transport.

Every scene is rendered by Ercuts (through ``bpy.ops.render.render`` and the add-on) and
by Cycles (CPU, no denoising, no clamping, 1-pixel box filter like the core's uniform
pixel jitter, the same path length: Cycles counts bounces after the first hit, so
``max_bounces = max_depth − 1``), and the linear EXR values are compared.

Neutralised differences: Cycles shows area lights to the camera, so they are kept out
of view (and hidden from camera rays); point/spot radius and sun angle are 0 (the core
renders points and a delta sun); the view transform does not touch EXR values.

These tests need the core renderer: they import it at module level, so a missing core
makes them fail, not skip.
"""
from __future__ import annotations

import math

import bpy
import numpy as np
import pytest

import blender_helpers as h
import ercuts_core  # noqa: F401  (a missing core must fail these tests)

W, H = 64, 48


def _cycles(scene, max_depth: int, samples: int, seed: int = 0) -> None:
    c = scene.cycles
    c.device = "CPU"
    c.samples = samples
    c.seed = seed
    c.use_denoising = False
    c.use_adaptive_sampling = False
    c.pixel_filter_type = "BOX"
    c.filter_width = 1.0
    c.sample_clamp_direct = 0.0
    c.sample_clamp_indirect = 0.0
    c.light_sampling_threshold = 0.0
    c.caustics_reflective = c.caustics_refractive = True
    c.max_bounces = max_depth - 1
    for key in ("diffuse_bounces", "glossy_bounces", "transmission_bounces", "volume_bounces"):
        setattr(c, key, max_depth - 1)


def render_both(tmp_path, max_depth=4, samples=64, cycles_samples=512, integrator="BDPT",
                seed=0, tag="scene"):
    """(ercuts, cycles) images (h, w, 4), top row first, of the current scene."""
    s = bpy.context.scene
    s.render.resolution_x, s.render.resolution_y = W, H
    s.render.resolution_percentage = 100
    s.ercuts.samples, s.ercuts.integrator, s.ercuts.max_depth = samples, integrator, max_depth
    s.ercuts.rough_samples = samples
    s.ercuts.seed = seed
    s.render.engine = "ERCUTS"
    ercuts = h.render_exr(tmp_path / f"{tag}_ercuts_{seed}.exr")
    _cycles(s, max_depth, cycles_samples, seed)
    s.render.engine = "CYCLES"
    cycles = h.render_exr(tmp_path / f"{tag}_cycles_{seed}.exr")
    return ercuts, cycles


def base_scene():
    """Grey floor and an orange box under a camera looking down at 34°; black world."""
    h.camera(location=(0, -4, 3), target=(0, 0, 0.3))
    h.plane("Floor", size=8, material=h.diffuse("Floor", (0.8, 0.8, 0.8)))
    h.box("Box", size=(1, 1, 1), location=(0.3, 0.3, 0.5), material=h.diffuse("Box", (0.8, 0.45, 0.2)))


def assert_means_agree(ercuts, cycles, rtol=0.03):
    e = ercuts[..., :3].mean(axis=(0, 1))
    c = cycles[..., :3].mean(axis=(0, 1))
    print(f"means: ercuts {np.round(e, 5)} cycles {np.round(c, 5)} rel {np.round((e - c) / c, 4)}")
    assert np.all(c > 1e-3), c
    assert np.allclose(e, c, rtol=rtol), f"ercuts {e} vs cycles {c} (rel {(e - c) / c})"


def _hide_from_camera(ob):
    ob.visible_camera = False


# --------------------------------------------------------------------------- light types

@pytest.mark.parametrize("integrator", ["BDPT", "PATH"])
def test_point_light(tmp_path, integrator):
    base_scene()
    h.light("POINT", location=(0, -0.5, 2), energy=300, color=(1, 0.9, 0.8), shadow_soft_size=0)
    e, c = render_both(tmp_path, integrator=integrator)
    assert_means_agree(e, c)


@pytest.mark.slow
@pytest.mark.xfail(bpy.app.version < (4, 0, 0), strict=True,
                   reason="Cycles 3.x spots dim by cos θ inside the cone; the scene description "
                          "has no field for it yet (renders ≈4-5 % brighter here)")
def test_spot_light(tmp_path):
    base_scene()
    h.light("SPOT", location=(0.8, -1.0, 2.5), target=(0.2, 0.3, 0), energy=800,
            color=(0.9, 1, 1), spot_size=math.radians(50), spot_blend=0.25, shadow_soft_size=0)
    e, c = render_both(tmp_path)
    assert_means_agree(e, c)


@pytest.mark.slow
def test_sun_light(tmp_path):
    base_scene()
    h.light("SUN", location=(2, -2, 4), target=(0, 0, 0), energy=2.0, color=(1, 0.95, 0.9), angle=0.0)
    e, c = render_both(tmp_path)
    assert_means_agree(e, c)


AREA_CASES = {
    "square": dict(shape="SQUARE", size=1.0),
    "rectangle_scaled": dict(shape="RECTANGLE", size=1.5, size_y=0.5, scale=(1, 2, 1)),
    "disk_tilted": dict(shape="DISK", size=1.2, tilt=20),
    "ellipse": dict(shape="ELLIPSE", size=1.5, size_y=0.6),
}


@pytest.mark.slow
@pytest.mark.parametrize("case", list(AREA_CASES))
def test_area_light(tmp_path, case):
    params = dict(AREA_CASES[case])
    scale = params.pop("scale", (1, 1, 1))
    tilt = params.pop("tilt", 0)
    base_scene()
    ob = h.light("AREA", location=(0, 0.2, 2.5), energy=200, color=(1, 0.9, 0.7), **params)
    ob.scale = scale
    ob.rotation_euler = (math.radians(tilt), 0, 0)
    _hide_from_camera(ob)
    e, c = render_both(tmp_path, tag=case)
    assert_means_agree(e, c)


@pytest.mark.slow
def test_emissive_mesh(tmp_path):
    base_scene()
    panel = h.plane("Panel", size=1.0, location=(0, 0.2, 2.2),
                    material=h.emission("Lamp", (1, 0.8, 0.6), 10.0))
    panel.rotation_euler = (math.pi, 0, 0)  # facing down (emission is two-sided anyway)
    e, c = render_both(tmp_path)
    assert_means_agree(e, c)


@pytest.mark.slow
def test_world_colour(tmp_path):
    base_scene()
    h.world((0.4, 0.5, 0.7), 1.5)
    e, c = render_both(tmp_path)
    assert_means_agree(e, c)


# --------------------------------------------------------------------------- camera

@pytest.mark.slow
@pytest.mark.parametrize("variant", ["persp_shift_vertical", "ortho_aspect"])
def test_silhouette_matches(tmp_path, variant):
    """Alpha (coverage) of objects over a transparent film covers the same pixels."""
    cam = h.camera(location=(0.5, -5, 2), target=(0, 0, 0.5), lens=45, sensor_fit="VERTICAL",
                   sensor_height=20.0, shift_x=0.08, shift_y=-0.05)
    s = bpy.context.scene
    if variant == "ortho_aspect":
        cam.data.type = "ORTHO"
        cam.data.ortho_scale = 4.0
        s.render.pixel_aspect_x = 1.5
    h.uv_sphere(radius=0.7, location=(-0.6, 0, 0.7), material=h.diffuse())
    box = h.box("Box", size=(0.8, 0.8, 1.6), location=(0.9, 0.4, 0.8), material=h.diffuse())
    box.rotation_euler = (0, 0, 0.5)
    h.light("SUN", energy=1.0, angle=0.0)
    s.render.film_transparent = True
    e, c = render_both(tmp_path, max_depth=1, samples=128, cycles_samples=128, tag=variant)
    ea, ca = e[..., 3], c[..., 3]
    print(f"alpha: mean {ea.mean():.4f}/{ca.mean():.4f}, mean|d| {np.abs(ea - ca).mean():.4f}, "
          f"max|d| {np.abs(ea - ca).max():.3f}, mask diff {np.count_nonzero((ea > 0.5) != (ca > 0.5))}")
    assert 0.05 < ca.mean() < 0.6  # the objects are in view, not filling it
    assert np.abs(ea - ca).mean() < 0.01
    assert np.abs(ea - ca).max() < 0.25  # edge pixels: both ≈ coverage, 128 samples each
    assert np.count_nonzero((ea > 0.5) != (ca > 0.5)) <= 0.01 * ea.size


# --------------------------------------------------------------------------- full transport

def _block_z(ercuts, cycles, block=8):
    """z-scores of the difference of block means (block×block pixels, per channel).

    ``ercuts``/``cycles`` are pairs of renders with different seeds. The variance of a
    block mean is estimated from the per-pixel seed differences inside the block, which
    is far steadier than a per-pixel estimate; a 1 % relative floor covers blocks that
    are noise-free in both (directly seen emitters).
    """
    def blocks(x):
        h, w, c = x.shape
        return x.reshape(h // block, block, w // block, block, c).mean(axis=(1, 3))

    def mean_var(pair):
        a, b = (x[..., :3].astype(np.float64) for x in pair)
        return blocks((a + b) / 2), blocks((a - b) ** 2 / 4) / block**2

    me, ve = mean_var(ercuts)
    mc, vc = mean_var(cycles)
    return (me - mc) / np.sqrt(ve + vc + (0.01 * mc) ** 2 + 1e-12)


def assert_seed_pairs_agree(runs, rtol, tag):
    """``runs``: [(ercuts, cycles)] of two seeds. Image means within ``rtol`` and 8×8-block
    z-scores (:func:`_block_z`) within the noise: mean z² < 1.6 and max |z| < 4.5."""
    e_pair, c_pair = [r[0] for r in runs], [r[1] for r in runs]
    assert_means_agree((e_pair[0] + e_pair[1]) / 2, (c_pair[0] + c_pair[1]) / 2, rtol=rtol)
    zb = _block_z(e_pair, c_pair)
    chi2 = float(np.mean(zb ** 2))
    print(f"{tag}: 8×8 blocks mean z² {chi2:.2f}, max |z| {np.abs(zb).max():.2f}")
    assert chi2 < 1.6, f"8×8 blocks: mean z² = {chi2:.2f}, a systematic difference beyond the noise"
    assert np.abs(zb).max() < 4.5, f"8×8 block off by {np.abs(zb).max():.1f}σ"


def _pixel_z(ercuts, cycles):
    """Per-pixel z-scores, the seed-difference variance smoothed over 5×5 pixels."""
    def mean_var(pair):
        a, b = (x[..., :3].astype(np.float64) for x in pair)
        v = (a - b) ** 2 / 4
        pad = np.pad(v, ((2, 2), (2, 2), (0, 0)), mode="edge")
        smooth = sum(pad[i:i + a.shape[0], j:j + a.shape[1]] for i in range(5) for j in range(5)) / 25
        return (a + b) / 2, smooth

    me, ve = mean_var(ercuts)
    mc, vc = mean_var(cycles)
    return (me - mc) / np.sqrt(ve + vc + (0.01 * mc) ** 2 + 1e-12)


@pytest.mark.slow
def test_cornell_box_per_pixel(tmp_path):
    import os

    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    bpy.ops.wm.open_mainfile(filepath=os.path.join(root, "blend_scenes", "cornell_box.blend"))
    runs = [render_both(tmp_path, max_depth=6, samples=48, cycles_samples=1024, seed=seed,
                        tag="cornell") for seed in (1, 2)]
    e_pair, c_pair = [r[0] for r in runs], [r[1] for r in runs]
    assert_means_agree((e_pair[0] + e_pair[1]) / 2, (c_pair[0] + c_pair[1]) / 2, rtol=0.02)
    zb = _block_z(e_pair, c_pair)
    zp = _pixel_z(e_pair, c_pair)
    chi2 = float(np.mean(zb ** 2))
    outliers = float(np.mean(np.abs(zp) > 5))
    print(f"cornell: 8×8 blocks mean z² {chi2:.2f}, max |z| {np.abs(zb).max():.2f}; "
          f"pixels beyond 5σ {outliers:.3%}")
    # A 2 % global bias gives mean z² ≈ 1.9, a 10 % bias on a 16×16 patch max |z| ≈ 12.
    assert chi2 < 1.6, f"8×8 blocks: mean z² = {chi2:.2f}, a systematic difference beyond the noise"
    assert np.abs(zb).max() < 4.5, f"8×8 block off by {np.abs(zb).max():.1f}σ"
    assert outliers < 0.003, f"{outliers:.2%} of pixel channels beyond 5σ"
