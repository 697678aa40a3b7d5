"""Output files are readable like any other file the user writes: the atomic writers
(:mod:`ercuts_core.atomic`) give a new file ``0o666 & ~umask`` — not ``tempfile.mkstemp``'s
private 0o600, which hid renders from the other users of a shared render node — and keep
the mode of a file they replace. Checked under umask 022 and 077 for every writer: EXR,
PNG, the ``.npz`` description and plain text through ``atomic_open`` (the add-on's JSON
sidecar uses it; ``tests/blender/test_sidecar_permissions.py`` checks the sidecar)."""
from __future__ import annotations

import os
import stat

import numpy as np
import pytest

from ercuts_core.atomic import atomic_open
from ercuts_core.description import save_npz
from ercuts_core.image_io import write_exr, write_png
from ercuts_core.scenes import cornell_box

IMAGE = np.full((4, 6, 4), 0.5, np.float32)


def _write_text(path):
    with atomic_open(path, "w") as fh:
        fh.write("{}")


WRITERS = {
    "exr": lambda path: write_exr(path, IMAGE),
    "png": lambda path: write_png(path, IMAGE),
    "npz": lambda path: save_npz(cornell_box(8, 6), path),
    "json": _write_text,
}


@pytest.fixture
def umask():
    """Set the process umask for the test; restored afterwards."""
    old = os.umask(0o022)
    try:
        yield os.umask
    finally:
        os.umask(old)


def mode(path) -> int:
    return stat.S_IMODE(os.stat(path).st_mode)


@pytest.mark.parametrize("kind", sorted(WRITERS))
@pytest.mark.parametrize("mask", [0o022, 0o077, 0o002])
def test_new_files_get_the_umask_mode(tmp_path, umask, kind, mask):
    umask(mask)
    path = tmp_path / f"out.{kind}"
    WRITERS[kind](path)
    assert mode(path) == 0o666 & ~mask
    assert os.listdir(tmp_path) == [path.name]          # no temporary file left


@pytest.mark.parametrize("kind", sorted(WRITERS))
def test_replaced_files_keep_their_mode(tmp_path, umask, kind):
    """Overwriting keeps the mode, as ``open(path, 'w')`` on an existing file does."""
    umask(0o077)
    path = tmp_path / f"out.{kind}"
    WRITERS[kind](path)
    os.chmod(path, 0o640)
    WRITERS[kind](path)
    assert mode(path) == 0o640
