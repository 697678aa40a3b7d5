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
