"""Renders of one scene by Ercuts and by Cycles over several seeds, compared by their own noise.

Shared by the Cycles-agreement tests of issue 15 (``test_rough_glass_cycles.py``,
``test_glass_cycles.py``): each engine renders the scene once per seed (Cycles as in
``test_cycles_agreement._cycles`` plus Filter Glossy 0), and
:func:`stats.compare_images` tests the block means (z-scores from the renders' variance,
χ² over the blocks, Šidák on the largest |z|). Cycles renders are cached per scene tag, so
the three integrators of a case share them.
"""
from __future__ import annotations

import os
import sys

import bpy
import numpy as np

import blender_helpers as h
from test_cycles_agreement import H, W, _cycles

TESTS = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
if TESTS not in sys.path:
    sys.path.insert(0, TESTS)
from stats import ImageComparison, compare_images  # noqa: E402

#: Seeds per engine: four renders give each pixel three degrees of freedom of variance and the
#: correlated-noise inflation (ERCUTS's VPLs, BDPT's splats) a usable estimate.
#: ``ERCUTS_TEST_SEEDS=5,6,7,8`` reruns the tests on other seeds (calibration checks).
SEEDS = tuple(int(x) for x in os.environ.get("ERCUTS_TEST_SEEDS", "1,2,3,4").split(","))
#: ERCUTS's own passes (rough BDPT image 16 spp, 32 direct-light passes), as in
#: ``test_soft_lights_cycles.py``.
ERCUTS_SETTINGS = dict(rough_samples=16, direct_samples=32)
_CYCLES: dict[tuple, np.ndarray] = {}
#: Set to 1 to run the error-injection tests (each renders Ercuts with a wrong parameter and
#: asserts that the comparison fails; the numbers in the docstrings come from them).
INJECT = os.environ.get("ERCUTS_INJECT_ERROR") == "1"


def unsampled_emission(name: str, color=(1, 1, 1), strength: float = 1.0):
    """An emission material that Cycles does not light-sample (it is found by BSDF sampling
    only: 5.x Emission Sampling 'None', 3.x Multiple Importance off). The core samples it as
    usual; both are unbiased for it. Why: Cycles' light samples taken *at* a rough-glass
    vertex overcount (``test_rough_glass_cycles.test_rough_slab_transmittance``)."""
    mat = h.emission(name, color, strength)
    if hasattr(mat.cycles, "emission_sampling"):
        mat.cycles.emission_sampling = "NONE"
    else:
        mat.cycles.sample_as_light = False
    return mat


def render_seeds(tmp_path, tag: str, integrator: str, *, samples: int, cycles_samples: int,
                 max_depth: int, size=(W, H), inject=None, seeds=SEEDS, cycles_seeds=SEEDS,
                 ercuts_settings=None):
    """(ercuts renders, cycles renders), one (h, w, 4) image per seed, of the current scene.

    ``inject``: optional callable run before the Ercuts renders that changes the scene and
    returns a callable restoring it (an error the comparison must detect); Cycles always
    renders the scene as built. ``seeds``/``cycles_seeds``: the seeds of each engine;
    ``ercuts_settings``: ERCUTS's settings (default :data:`ERCUTS_SETTINGS`).
    """
    s = bpy.context.scene
    s.render.resolution_x, s.render.resolution_y = size
    s.render.resolution_percentage = 100
    undo = inject() if inject is not None else None
    ercuts = []
    for seed in seeds:
        s.render.engine = "ERCUTS"
        e = s.ercuts
        e.integrator, e.samples, e.max_depth, e.seed = integrator, samples, max_depth, seed
        if integrator == "ERCUTS":
            for key, value in (ercuts_settings or ERCUTS_SETTINGS).items():
                setattr(e, key, value)
        ercuts.append(h.render_exr(tmp_path / f"{tag}_{integrator}_{seed}.exr"))
    if undo is not None:
        undo()
    cycles = []
    for seed in cycles_seeds:
        key = (tag, seed, cycles_samples, max_depth, tuple(size))
        if key not in _CYCLES:
            _cycles(s, max_depth, cycles_samples, seed)
            s.cycles.blur_glossy = 0.0
            s.render.engine = "CYCLES"
            _CYCLES[key] = h.render_exr(tmp_path / f"{tag}_cycles_{seed}.exr")
        cycles.append(_CYCLES[key])
    return ercuts, cycles


def compare(tag: str, ercuts, cycles, block: int = 8) -> ImageComparison:
    """:func:`stats.compare_images` of the two sets, printed."""
    result = compare_images(ercuts, cycles, block=block)
    print(f"{tag} [Blender {bpy.app.version_string}]: {result.summary()}")
    return result
