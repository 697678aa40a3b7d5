"""Camera: Blender's view plane, ray/raster round trips, border windows, importance normalisation."""
from __future__ import annotations

import numpy as np
import pytest

from ercuts_core.camera import Camera, render_window, view_plane
from ercuts_core.description import CameraDesc


def desc(**kw):
    base = dict(world_from_camera=np.eye(4), width=64, height=32)
    base.update(kw)
    return CameraDesc(**base)


def test_view_plane_matches_blender_view_frame():
    # Blender: AUTO 64x32, lens 50, sensor 36, shift_x 0.1 → view_frame x ∈ [−0.4, 0.6],
    # y ∈ [−0.25, 0.25] at z = −lens/sensor (blender.md §2.4). At z = −1 scale by sensor/lens.
    s = 36 / 50
    x0, x1, y0, y1 = view_plane(desc(lens=50, sensor_width=36, shift_x=0.1))
    np.testing.assert_allclose([x0, x1, y0, y1], np.array([-0.4, 0.6, -0.25, 0.25]) * s)


@pytest.mark.parametrize("fit,w,h,expect", [
    ("AUTO", 32, 64, (36 / 50 * 0.25, 36 / 50 * 0.5)),          # portrait: width of sensor spans y
    ("VERTICAL", 64, 32, (24 / 50, 24 / 50 * 0.5)),             # sensor_height spans y
    ("HORIZONTAL", 32, 64, (36 / 50 * 0.5, 36 / 50)),           # sensor_width spans x
])
def test_sensor_fit(fit, w, h, expect):
    x0, x1, y0, y1 = view_plane(desc(sensor_fit=fit, width=w, height=h))
    half_x, half_y = expect
    if fit == "VERTICAL":
        np.testing.assert_allclose([x1, y1], [24 / 50, 12 / 50])
    elif fit == "HORIZONTAL":
        np.testing.assert_allclose([x1, y1], [18 / 50, 36 / 50])
    else:
        np.testing.assert_allclose([x1, y1], [9 / 50, 18 / 50])


def test_ortho_plane_uses_ortho_scale():
    x0, x1, y0, y1 = view_plane(desc(projection="ORTHO", ortho_scale=4.0))
    np.testing.assert_allclose([x0, x1, y0, y1], [-2, 2, -1, 1])


def test_border_window_follows_blender_truncation():
    w = render_window(desc(width=100, height=50, use_border=True, border=(0.105, 0.2, 0.5, 0.9)))
    # x: int(10.5)=10 .. int(50)=50; y from bottom: int(10)=10 .. int(45)=45 → top y0 = 50-45
    assert (w.x0, w.y0, w.width, w.height) == (10, 5, 40, 35)


@pytest.mark.parametrize("proj", ["PERSP", "ORTHO"])
def test_rays_and_raster_round_trip(proj):
    rot = np.eye(4)
    rot[:3, :3] = np.linalg.qr(np.random.default_rng(3).normal(size=(3, 3)))[0]
    if np.linalg.det(rot[:3, :3]) < 0:
        rot[:3, 0] *= -1
    rot[:3, 3] = [1, 2, 3]
    cam = Camera(desc(world_from_camera=rot, projection=proj, shift_y=-0.2))
    raster = np.random.default_rng(4).uniform([0, 0], [64, 32], size=(1000, 2))
    o, d = cam.generate_rays(raster)
    back, ok = cam.raster_of(o + 3.7 * d)
    assert ok.all()
    np.testing.assert_allclose(back, raster, atol=1e-7)


def test_importance_integrates_to_one_per_pixel():
    """∫ W_e·G dA over a plane covering the view = number of window pixels (per-pixel normalisation)."""
    cam = Camera(desc(width=40, height=30, use_border=True, border=(0.25, 0.0, 1.0, 0.5)))
    rng = np.random.default_rng(0)
    n = 400_000
    half = 3.0
    p = np.c_[rng.uniform(-half, half, n), rng.uniform(-half, half, n), np.full(n, -2.0)]
    con = cam.connect(p)
    cos_p = np.abs(con.wi[:, 2])
    est = (con.factor * cos_p) * (2 * half) ** 2
    mean, se = est.mean(), est.std() / np.sqrt(n)
    assert abs(mean - cam.window.n_pixels) < 4 * se, (mean, cam.window.n_pixels, se)


def test_window_raster_and_pixel_round_trip():
    """Window.raster → Window.pixel is the identity on the window; outside positions are
    flagged (or clamped with clip=True)."""
    from ercuts_core.camera import Window

    w = Window(3, 5, 7, 4)
    pix = np.arange(w.n_pixels)
    raster = w.raster(pix)
    assert raster[0].tolist() == [3, 5] and raster[-1].tolist() == [9, 8]
    back, inside = w.pixel(raster + 0.5)
    assert inside.all() and (back == pix).all()
    outside = np.array([[2.9, 5.5], [10.0, 5.5], [3.5, 4.9], [3.5, 9.0]])
    _, inside = w.pixel(outside)
    assert not inside.any()
    clipped, inside = w.pixel(outside, clip=True)
    assert inside.all() and clipped.tolist() == [0, 6, 0, 21]
