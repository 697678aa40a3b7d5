"""The memory estimate (ercuts_core.memory): batches follow the budget, an impossible render
is refused before allocating, and the estimate bounds what a render really allocates."""
from __future__ import annotations

import tracemalloc

import numpy as np
import pytest

from ercuts_core import RenderSettings, render, scenes
from ercuts_core.memory import MIB, MemoryBudgetError, plan, plan_for


@pytest.mark.parametrize("integrator,n,phase", [("PATH", 1920 * 1080, "batch"), ("BDPT", 1920 * 1080, "batch"),
                                                ("ERCUTS", 640 * 480, "seed batch")])
def test_batches_shrink_to_fit_the_budget(integrator, n, phase):
    roomy = plan(n, 10_000, RenderSettings(integrator=integrator, memory_budget_mb=0))
    assert max(roomy.phases, key=roomy.phases.get) == phase
    budget_mb = int(roomy.total / MIB) - 50
    tight = plan(n, 10_000, RenderSettings(integrator=integrator, memory_budget_mb=budget_mb))
    assert tight.total <= budget_mb * MIB < roomy.total
    assert tight.phases[phase] < roomy.phases[phase]


def test_no_budget_never_refuses():
    p = plan(100_000 * 100_000, 10**8, RenderSettings(memory_budget_mb=0))
    assert p.total > 10**12


def test_default_budget_fits_a_1080p_render_with_default_settings():
    p = plan(1920 * 1080, 100_000, RenderSettings())
    assert p.total <= 4096 * MIB


def test_impossible_render_is_refused_before_allocating():
    desc = scenes.cornell_box(64, 48)
    big = desc.replace(camera=desc.camera.__class__(**{**vars(desc.camera), "width": 40000, "height": 30000}))
    tracemalloc.start()
    try:
        with pytest.raises(MemoryBudgetError, match=r"about \d+ MiB .*memory budget of 4096 MiB"):
            render(big, RenderSettings())
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert peak < 64 * MIB     # nothing window-sized was allocated (the window needs ~10⁵ MiB)


@pytest.mark.parametrize("integrator", ["PATH", "BDPT", "ERCUTS"])
def test_estimate_bounds_the_allocated_peak(integrator):
    """tracemalloc sees numpy's allocations; the estimate must not be lower than the peak."""
    desc = scenes.s_corridor(48, 36)
    s = RenderSettings(integrator=integrator, samples=2, max_depth=4, chain_length=10, e1_samples=16)
    estimate = plan_for(desc, s).total
    tracemalloc.start()
    try:
        result = render(desc, s)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert result.stats["memory_estimate_mb"] == pytest.approx(estimate / MIB)
    assert peak <= estimate, (peak / MIB, estimate / MIB)


def test_tight_budget_still_renders_with_smaller_batches():
    desc = scenes.cornell_box(64, 48)
    roomy = plan_for(desc, RenderSettings(integrator="PATH"))
    budget = int((roomy.total - 0.5 * roomy.phases["batch"]) / MIB) + 1
    s = RenderSettings(integrator="PATH", samples=2, memory_budget_mb=budget)
    assert plan_for(desc, s).batch_pixels < roomy.batch_pixels
    r = render(desc, s)
    assert r.stats["memory_estimate_mb"] <= budget and np.isfinite(r.image).all()
    assert r.image[..., :3].mean() > 0


def test_environment_map_counts_in_the_plan():
    """An HDRI world (its texels and sampling tables) is part of the estimate."""
    from ercuts_core.description import WorldMap
    from ercuts_core.memory import ENV_TEXEL_BYTES

    desc = scenes.cornell_box(32, 24)
    h, w = 512, 1024
    with_map = desc.replace(world_map=WorldMap(np.ones((h, w, 3), np.float32), np.eye(3, dtype=np.float32)))
    s = RenderSettings(integrator="PATH", memory_budget_mb=0)
    grown = plan_for(with_map, s).total - plan_for(desc, s).total
    assert grown == h * w * (12 + ENV_TEXEL_BYTES)
