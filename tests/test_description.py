"""Scene description: dtypes, contiguity, and the .npz round trip."""
from __future__ import annotations

import numpy as np

from ercuts_core import load_npz, save_npz
from ercuts_core.scenes import SCENES, cornell_box, point_lit_box


def _assert_same(a, b):
    for part in ("mesh", "materials", "point_lights", "sun_lights", "area_lights", "camera"):
        pa, pb = getattr(a, part), getattr(b, part)
        for name, va in vars(pa).items():
            vb = getattr(pb, name)
            if isinstance(va, np.ndarray):
                assert va.dtype == vb.dtype and va.shape == vb.shape, (part, name)
                np.testing.assert_array_equal(va, vb)
            else:
                assert va == vb, (part, name)
    np.testing.assert_array_equal(a.world_radiance, b.world_radiance)
    assert a.object_names == b.object_names


def test_arrays_are_contiguous_with_fixed_dtypes():
    d = cornell_box()
    assert d.mesh.positions.dtype == np.float32 and d.mesh.positions.flags.c_contiguous
    assert d.mesh.triangles.dtype == np.int32 and d.mesh.triangles.shape[1] == 3
    assert d.materials.base_color.dtype == np.float32
    assert d.camera.world_from_camera.dtype == np.float64


def test_npz_round_trip_every_builtin(tmp_path):
    for name, make in SCENES.items():
        d = make()
        path = tmp_path / f"{name}.npz"
        save_npz(d, path)
        _assert_same(d, load_npz(path))


def test_npz_round_trip_with_lights_border_and_normals(tmp_path):
    d = point_lit_box()
    cam = d.camera.__class__(**{**vars(d.camera), "use_border": True, "border": (0.1, 0.2, 0.6, 0.9),
                                "projection": "ORTHO", "sensor_fit": "VERTICAL"})
    mesh = d.mesh.__class__(d.mesh.positions, d.mesh.triangles, d.mesh.material_ids, d.mesh.object_ids,
                            normals=np.tile([[0, 1, 0]], (len(d.mesh.positions), 1)),
                            smooth=np.arange(d.mesh.n_triangles) % 2 == 0)
    d = d.replace(camera=cam, mesh=mesh, world_radiance=np.array([0.1, 0.2, 0.3]))
    save_npz(d, tmp_path / "x.npz")
    _assert_same(d, load_npz(tmp_path / "x.npz"))


def test_save_is_atomic_and_leaves_no_temp_files(tmp_path):
    save_npz(cornell_box(), tmp_path / "a.npz")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.npz"]


def test_npz_round_trip_with_soft_lights_and_depth_of_field(tmp_path):
    """Light radius and shape, sun angle, area spread and the thin-lens fields survive the
    round trip; a file written before they existed loads with their defaults."""
    from ercuts_core import AreaLights, PointLights, SunLights

    d = point_lit_box()
    pl = d.point_lights
    pts = PointLights(pl.position, pl.intensity, pl.direction, pl.cos_half_angle, pl.blend,
                      [0.1, 0.25], pl.object_ids, [True, False])
    suns = SunLights([[0, -1, 0]], [[2, 2, 2]], [0.05], [0])
    areas = AreaLights([[0, 1.9, 0]], [[0.2, 0, 0]], [[0, 0, 0.2]], [[0, -1, 0]], [[5, 5, 5]], [1], [0],
                       [0.7])
    cam = d.camera.__class__(**{**vars(d.camera), "aperture_radius": 0.02, "focus_distance": 1.7,
                                "aperture_blades": 5, "aperture_rotation": 0.3, "aperture_ratio": 1.4})
    d = d.replace(point_lights=pts, sun_lights=suns, area_lights=areas, camera=cam)
    save_npz(d, tmp_path / "soft.npz")
    back = load_npz(tmp_path / "soft.npz")
    _assert_same(d, back)
    assert back.point_lights.sphere.tolist() == [True, False] and back.camera.aperture_blades == 5
    # An old file: no sphere/spread/lens keys
    with np.load(tmp_path / "soft.npz") as z:
        old = {k: z[k] for k in z.files if not k.endswith((".sphere", ".spread")) and "aperture" not in k
               and "focus" not in k}
    np.savez(tmp_path / "old.npz", **old)
    o = load_npz(tmp_path / "old.npz")
    assert o.point_lights.sphere.tolist() == [False, False]
    np.testing.assert_allclose(o.area_lights.spread, np.float32(np.pi))
    assert o.camera.aperture_radius == 0.0 and o.camera.focus_distance == 10.0
