"""Large work (slow): a 1M-triangle scene through the add-on, 10^5+ VPLs within the memory
budget, and a 100-frame batch render whose memory does not grow from frame to frame.

Timings are printed (run with ``-s``), never asserted; the export time of the 1M-triangle
scene is reported in the README's robustness section.
"""
from __future__ import annotations

import time
import tracemalloc

import bpy
import numpy as np
import pytest

import blender_helpers as bh
from addon import engine
from test_faults import rss_mb

pytestmark = pytest.mark.slow

#: Allowed growth of the resident set per frame over a 100-frame batch render [MiB/frame]
#: (a leak of one 8×6 film per frame is far below this; a leaked scene or G-buffer is not).
RSS_SLOPE_MB = 0.05


def grid(name: str, n: int, size: float = 10.0):
    """An n×n-quad grid (2n² triangles) built with foreach_set (no per-vertex Python)."""
    xs = np.linspace(-size / 2, size / 2, n + 1)
    gx, gy = np.meshgrid(xs, xs, indexing="ij")
    co = np.stack([gx.ravel(), gy.ravel(), 0.02 * np.sin(gx.ravel() * 7) * np.cos(gy.ravel() * 5)], 1)
    i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    v0 = (i * (n + 1) + j).ravel()
    quads = np.stack([v0, v0 + n + 1, v0 + n + 2, v0 + 1], 1)
    me = bpy.data.meshes.new(name)
    me.vertices.add(len(co))
    me.vertices.foreach_set("co", co.astype(np.float32).ravel())
    me.loops.add(quads.size)
    me.loops.foreach_set("vertex_index", quads.astype(np.int32).ravel())
    me.polygons.add(len(quads))
    me.polygons.foreach_set("loop_start", np.arange(0, quads.size, 4, dtype=np.int32))
    if bpy.app.version < (4, 0, 0):
        me.polygons.foreach_set("loop_total", np.full(len(quads), 4, np.int32))
    me.update()
    me.validate()
    return bh.link(bpy.data.objects.new(name, me))


def test_million_triangles_export_and_render(tmp_path):
    bh.setup_render(32, 24, samples=1, integrator="PATH", max_depth=2)
    floor = grid("Terrain", 708)
    floor.data.materials.append(bh.diffuse("Grey"))
    bh.camera(location=(0, -8, 6), target=(0, 0, 0))
    bh.light("SUN", energy=3.0)
    t0 = time.perf_counter()
    exported = bh.export()
    seconds = time.perf_counter() - t0
    n = exported.stats["triangles"]
    print(f"\n1M-triangle export: {n} triangles in {seconds:.2f} s")
    assert n == 2 * 708 * 708 >= 1_000_000
    img = bh.render_exr(tmp_path / "terrain.exr")
    print(f"render: {engine.last_render['summary']}, export {engine.last_render['export_seconds']:.2f} s")
    assert np.isfinite(img).all() and img[..., :3].mean() > 0
    assert engine.last_render["stats"]["nonfinite_samples"] == 0


def test_hundred_thousand_vpls_stay_within_the_memory_budget():
    """A render with 10^5+ VPLs: the arrays it allocates (tracemalloc) stay under both
    the estimate the budget is checked against and the budget itself."""
    from ercuts_core import RenderSettings, render, scenes
    from ercuts_core.memory import MIB, plan_for

    desc = scenes.cornell_box(160, 120)
    s = RenderSettings(rough_samples=1, max_depth=4, chains_per_pixel=7.0, max_chains=1 << 20,
                       chain_length=12, e1_samples=8, max_cut_size=64, memory_budget_mb=1024)
    estimate = plan_for(desc, s).total
    tracemalloc.start()
    try:
        t0 = time.perf_counter()
        result = render(desc, s)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    print(f"\n{result.stats['vpls']} VPLs, peak {peak / MIB:.0f} MiB of arrays, estimate "
          f"{estimate / MIB:.0f} MiB, {time.perf_counter() - t0:.0f} s")
    assert result.stats["vpls"] >= 100_000
    assert peak <= estimate <= s.memory_budget_mb * MIB
    assert np.isfinite(result.image).all() and result.stats["nonfinite_samples"] == 0


def test_hundred_frame_batch_render_does_not_grow_memory(tmp_path):
    s = bh.setup_render(8, 6, samples=1, integrator="PATH", max_depth=2)
    bh.plane("Floor", material=bh.diffuse("Grey"))
    bh.camera(location=(0, 0, 3))
    lamp = bh.light("POINT", location=(0, 0, 2))
    lamp.keyframe_insert("location", frame=1)
    lamp.location = (1, 0, 2)
    lamp.keyframe_insert("location", frame=100)
    s.frame_start, s.frame_end = 1, 100
    s.render.filepath = str(tmp_path / "f_####")
    s.render.image_settings.file_format = "OPEN_EXR"
    samples = []

    def record(*_):
        samples.append(rss_mb())

    bpy.app.handlers.render_post.append(record)
    try:
        assert bpy.ops.render.render(animation=True) == {"FINISHED"}
    finally:
        bpy.app.handlers.render_post.remove(record)
    assert len(samples) == 100 and len(list(tmp_path.glob("f_*.exr"))) == 100
    frames = np.arange(20, 100)                       # after warm-up
    slope = np.polyfit(frames, np.array(samples[20:]), 1)[0]
    print(f"\nRSS {samples[0]:.0f} → {samples[-1]:.0f} MiB over 100 frames, slope {slope:.4f} MiB/frame")
    assert slope < RSS_SLOPE_MB
