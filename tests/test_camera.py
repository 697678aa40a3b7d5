"""Camera: Blender's view plane, ray/raster round trips, border windows, importance normalisation."""
from __future__ import annotations

import numpy as np
import pytest

from ercuts_core.camera import Camera, render_window, view_plane
from ercuts_core.description import CameraDesc

try:
    from tests.stats import PlanarDomain, chi2_test
except ImportError:  # tests/ is not a package: pytest put tests/ itself on sys.path
    from stats import PlanarDomain, chi2_test


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


# --------------------------------------------------------------------------- thin lens
def lens_camera(**kw):
    rot = np.eye(4)
    rot[:3, :3] = np.linalg.qr(np.random.default_rng(5).normal(size=(3, 3)))[0]
    if np.linalg.det(rot[:3, :3]) < 0:
        rot[:3, 0] *= -1
    rot[:3, 3] = [0.5, -1.0, 2.0]
    base = dict(world_from_camera=rot, aperture_radius=0.08, focus_distance=3.0)
    base.update(kw)
    return Camera(desc(**base))


def test_thin_lens_rays_of_a_raster_position_meet_on_the_plane_in_focus():
    """Cycles: every lens point's ray through a raster position passes its point at depth
    focus_distance; the lens points lie in the aperture (radius, x ÷ ratio)."""
    cam = lens_camera(aperture_ratio=2.0)
    rng = np.random.default_rng(1)
    raster = np.repeat(rng.uniform([0, 0], [64, 32], size=(50, 2)), 40, axis=0)
    o, d = cam.generate_rays(raster, rng.random((len(raster), 2)))
    local_o = (o - cam.position) @ cam.rotation
    assert np.abs(local_o[:, 2]).max() < 1e-12
    assert ((local_o[:, 0] * 2.0) ** 2 + local_o[:, 1] ** 2 <= 0.08**2 + 1e-12).all()
    t = 3.0 / (-(d @ cam.rotation)[:, 2])
    focus = (o + d * t[:, None] - cam.position) @ cam.rotation
    np.testing.assert_allclose(focus[:, 2], -3.0, atol=1e-12)
    pin_o, pin_d = Camera(desc(world_from_camera=cam.desc.world_from_camera)).generate_rays(raster)
    pin_focus = pin_o + pin_d * (3.0 / (-(pin_d @ cam.rotation)[:, 2]))[:, None]
    np.testing.assert_allclose(o + d * t[:, None], pin_focus, atol=1e-10)


def test_thin_lens_connection_is_the_camera_ray_backwards():
    """connect(p, u) gives the raster whose camera ray from the same lens point passes p;
    raster_of with that origin and lens_point_of invert each other."""
    cam = lens_camera(aperture_blades=6, aperture_rotation=0.4)
    rng = np.random.default_rng(2)
    n = 2000
    raster = rng.uniform([0, 0], [64, 32], size=(n, 2))
    u = rng.random((n, 2))
    o, d = cam.generate_rays(raster, u)
    p = o + d * rng.uniform(0.5, 8.0, n)[:, None]
    con = cam.connect(p, u)
    assert con.valid.all()
    np.testing.assert_allclose(con.origin, o, atol=1e-12)
    np.testing.assert_allclose(con.raster, raster, atol=1e-7)
    np.testing.assert_allclose(-con.wi, d, atol=1e-9)
    np.testing.assert_allclose(cam.lens_point_of(raster, p), o, atol=1e-9)
    o2, d2 = cam.rays_from(raster, o)
    np.testing.assert_allclose(d2, d, atol=1e-12)


def test_thin_lens_importance_integrates_to_one_per_pixel():
    """With a lens point per sample the connection still integrates to the window's pixel
    count over a plane covering the view (the uniform lens density cancels W_e's 1/A_lens)."""
    cam = Camera(desc(width=40, height=30, aperture_radius=0.3, focus_distance=1.0,
                      use_border=True, border=(0.25, 0.0, 1.0, 0.5)))
    rng = np.random.default_rng(0)
    n = 400_000
    half = 3.0
    p = np.c_[rng.uniform(-half, half, n), rng.uniform(-half, half, n), np.full(n, -2.0)]
    con = cam.connect(p, rng.random((n, 2)))
    est = con.factor * np.abs(con.wi[:, 2]) * (2 * half) ** 2
    mean, se = est.mean(), est.std() / np.sqrt(n)
    assert abs(mean - cam.window.n_pixels) < 4 * se, (mean, cam.window.n_pixels, se)


@pytest.mark.parametrize("blades, ratio", [(0, 1.0), (5, 1.6)])
def test_aperture_points_are_uniform(blades, ratio):
    """chi² of the lens points against the uniform density of the disk / blade polygon."""
    from ercuts_core.sampling import regular_polygon_area

    cam = lens_camera(aperture_radius=1.0, aperture_blades=blades, aperture_rotation=0.3,
                      aperture_ratio=ratio)
    rot = 0.3                                          # the first edge's normal
    area = (regular_polygon_area(blades) if blades else np.pi) / ratio

    def inside(q):
        x, y = q[:, 0] * ratio, q[:, 1]
        if not blades:
            return x * x + y * y <= 1.0
        ang = np.arctan2(y, x) - rot
        sector = np.round(ang / (2 * np.pi / blades))
        local = ang - sector * 2 * np.pi / blades           # angle from the edge's normal
        return np.hypot(x, y) * np.cos(local) <= np.cos(np.pi / blades) + 1e-12

    ok, msg = chi2_test(lambda u: cam.lens_points(u)[:, :2], lambda q: inside(q) / area,
                        n_samples=200_000, res_theta=31, res_phi=31, test_count=2,
                        domain=PlanarDomain(((-1.0, 1.0), (-1.0, 1.0))))
    assert ok, msg


def test_depth_of_field_rays_need_lens_samples():
    cam = lens_camera()
    with pytest.raises(ValueError, match="lens samples"):
        cam.generate_rays(np.zeros((1, 2)))
    assert cam.lens_samples(np.random.default_rng(0), 3).shape == (3, 2)
    assert Camera(desc()).lens_samples(np.random.default_rng(0), 3) is None
