"""The JSON statistics sidecar is readable like the frame beside it: ``0o666 & ~umask``
(it was written through ``tempfile.mkstemp`` and stayed private, 0o600, on a shared
render node). The core's writers are checked in ``tests/test_file_permissions.py``."""
from __future__ import annotations

import os
import stat

import pytest

import blender_helpers as h


@pytest.mark.parametrize("mask", [0o022, 0o077])
def test_sidecar_gets_the_umask_mode_like_the_frame(tmp_path, mask):
    h.camera(location=(0, 0, 5))
    h.plane("Floor", size=20, material=h.diffuse("Floor"))
    h.light("POINT", location=(0, 0, 3), energy=200)
    s = h.setup_render(16, 12, samples=1)
    s.ercuts.write_sidecar = True
    old = os.umask(mask)
    try:
        h.render_exr(tmp_path / "frame.exr")
    finally:
        os.umask(old)
    modes = {name: stat.S_IMODE(os.stat(tmp_path / name).st_mode) for name in os.listdir(tmp_path)}
    assert modes == {"frame.exr": 0o666 & ~mask, "frame.ercuts.json": 0o666 & ~mask}
