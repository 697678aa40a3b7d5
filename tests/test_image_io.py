"""Output files are written atomically (ercuts_core.image_io): a writer that dies half-way
leaves the earlier file untouched and no temporary file behind. (Core test: the OpenEXR
module cannot be used inside Blender 3.4's process, whose own OpenEXR library clashes.)"""
from __future__ import annotations

import os

import numpy as np
import pytest


def test_exr_writes_are_atomic(tmp_path, monkeypatch):
    """A writer that dies half-way leaves the earlier file untouched and no temp file."""
    import OpenEXR

    from ercuts_core.image_io import read_exr, write_exr

    path = tmp_path / "image.exr"
    good = np.full((6, 8, 4), 0.25, np.float32)
    write_exr(path, good)
    before = path.read_bytes()

    class Interrupted(BaseException):
        pass

    def truncated_write(self, filename):
        with open(filename, "wb") as f:
            f.write(before[: len(before) // 2])
        raise Interrupted()

    monkeypatch.setattr(OpenEXR.File, "write", truncated_write)
    with pytest.raises(Interrupted):
        write_exr(path, np.zeros((6, 8, 4), np.float32))
    monkeypatch.undo()
    assert path.read_bytes() == before and os.listdir(tmp_path) == ["image.exr"]
    np.testing.assert_array_equal(read_exr(path)["RGBA"], good)


def test_png_writes_are_atomic(tmp_path, monkeypatch):
    from ercuts_core import image_io

    path = tmp_path / "image.png"
    image_io.write_png(path, np.full((6, 8, 4), 0.5, np.float32))
    before = path.read_bytes()
    monkeypatch.setattr(image_io, "encode_png", lambda rgb8: (_ for _ in ()).throw(OSError("disk full")))
    with pytest.raises(OSError):
        image_io.write_png(path, np.zeros((6, 8, 4), np.float32))
    assert path.read_bytes() == before and os.listdir(tmp_path) == ["image.png"]
