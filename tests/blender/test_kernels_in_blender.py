"""The gather's numba kernels inside Blender, next to embreex (issue 17): in the bpy module
and in Debian's ``blender -b`` 3.4.1 (which links Embree 3, so the add-on loads embreex with
RTLD_DEEPBIND; llvmlite carries its own LLVM, bpy 5.0's OSL another). An ERCUTS render of
a small room through the add-on gives the same image with the compiled kernels as with
the numpy code, for the bounded and the stochastic gather."""
from __future__ import annotations

import sys

import bpy
import numpy as np
import pytest

import blender_helpers as h
from ercuts_core import kernels


def room():
    h.box("Room", size=(4, 4, 3), location=(0, 0, 1.5), material=h.diffuse("Wall"), inward=True)
    h.box("Pillar", size=(0.6, 0.6, 2.0), location=(0.4, 0.3, 1.0), material=h.diffuse("P", (0.5, 0.6, 0.7)))
    h.light("POINT", location=(-1.2, -1.0, 2.4), energy=300.0)
    bpy.context.scene.camera = h.camera(location=(1.6, -1.7, 1.5), target=(0, 0, 1.0), lens=24)


def test_numba_loads_next_to_embreex():
    assert kernels.NUMBA, kernels.WHY_NOT
    assert "embreex.rtcore_scene" in sys.modules or __import__("embreex.rtcore_scene")
    assert "llvmlite.binding" in sys.modules and kernels.enabled()


@pytest.mark.parametrize("gather", ["LIGHTCUTS", "STOCHASTIC"])
def test_ercuts_render_same_with_kernels_and_numpy(tmp_path, gather):
    room()
    s = h.setup_render(width=40, height=30, integrator="ERCUTS", samples=4, max_depth=8)
    s.ercuts.gather = gather
    s.ercuts.direct_samples = 4
    with kernels.backend("numba"):
        a = h.render_exr(tmp_path / "numba.exr")
    with kernels.backend("numpy"):
        b = h.render_exr(tmp_path / "numpy.exr")
    assert np.isfinite(a).all() and a[..., :3].mean() > 0.01
    np.testing.assert_allclose(a, b, rtol=1e-5, atol=1e-7)     # float32 EXR of equal images
