"""The pass loop shared by every integrator and phase (integrators/base.run_passes)."""
import time

from ercuts_core import RenderSettings
from ercuts_core.film import Film
from ercuts_core.integrators.base import Clock, run_passes
from ercuts_core.integrators.path import PathIntegrator
from ercuts_core.scene import BuiltScene
from ercuts_core.scenes import cornell_box
from ercuts_core.validate import sanitize


def test_a_phase_past_its_deadline_stops_after_its_first_pass():
    """run_passes with a phase deadline already past makes exactly one complete pass (a forced
    second one left a 1080p render's later phases no time), and without a deadline all."""
    scene = BuiltScene(sanitize(cornell_box(8, 6, "mesh")).desc)
    path = PathIntegrator(scene, RenderSettings(max_depth=2))
    clock = Clock(0.0, None)
    late = run_passes(path, Film(path.window), clock, samples=4, batch=16, phase="PATH",
                      deadline=time.perf_counter() - 1.0)
    full = run_passes(path, Film(path.window), clock, samples=4, batch=16, phase="PATH")
    assert late.passes_done == 1 and full.passes_done == 4
    assert late.image()[..., :3].sum() > 0
