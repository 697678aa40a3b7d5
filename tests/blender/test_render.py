"""The render path: engine → core → RenderResult → file, errors, warnings, cancel, time limit."""
from __future__ import annotations

import time

import bpy
import numpy as np
import pytest

import blender_helpers as h
import ercuts_core
from addon import engine as engine_module
from addon import framebuffer
from addon.engine import ErcutsRenderEngine
from ercuts_core.result import RenderResult


# --------------------------------------------------------------------------- framebuffer (pure)

def test_place_flips_rows_and_offsets_window():
    H = 6
    image = np.arange(2 * 3 * 4, dtype=np.float32).reshape(2, 3, 4)  # window 3×2 at (1, 1) from top
    out = framebuffer.place(image, (1, 1, 3, 2), H, (0, 0), (5, H))
    # Top window row (y=1 from top) lands at bottom-up row H-1-1 = 4.
    assert np.array_equal(out[4, 1:4], image[0])
    assert np.array_equal(out[3, 1:4], image[1])
    assert out[[0, 1, 2, 5]].sum() == 0 and out[:, 0].sum() == 0 and out[:, 4].sum() == 0


def test_place_into_border_buffer_clips():
    image = np.ones((4, 4, 4), np.float32)
    out = framebuffer.place(image, (2, 0, 4, 4), 8, (3, 5), (2, 2))  # window rows 4..7 bottom-up
    assert out.shape == (2, 2, 4)
    assert np.all(out[:, :] == 1)
    out = framebuffer.place(image, (0, 0, 4, 4), 8, (6, 0), (2, 2))  # no overlap
    assert out.sum() == 0


# --------------------------------------------------------------------------- synthetic core

def _coordinate_image_render(desc, settings=None, progress=None):
    """Stand-in for ercuts_core.render: pixel = (x + 0.5, y_from_top + 0.5, 7, 1) in full-frame pixels."""
    from ercuts_core.camera import render_window

    w = render_window(desc.camera)
    ys, xs = np.mgrid[w.y0:w.y0 + w.height, w.x0:w.x0 + w.width].astype(np.float32)
    image = np.stack([xs + 0.5, ys + 0.5, np.full_like(xs, 7), np.ones_like(xs)], axis=2)
    if progress is not None:
        progress(1.0, "synthetic")
    return RenderResult(image=image, window=w.rect,
                        full_size=(desc.camera.width, desc.camera.height))


@pytest.fixture
def synthetic_core(monkeypatch):
    monkeypatch.setattr(ercuts_core, "render", _coordinate_image_render)


def _scene(width=40, height=30):
    h.camera()
    h.plane(size=4)
    h.light("POINT", energy=100)
    return h.setup_render(width, height, samples=4)


def test_orientation_full_frame(tmp_path, synthetic_core):
    _scene(40, 30)
    img = h.render_exr(tmp_path / "full.exr")
    assert img.shape == (30, 40, 4)
    ys, xs = np.mgrid[0:30, 0:40]
    assert np.allclose(img[..., 0], xs + 0.5) and np.allclose(img[..., 1], ys + 0.5)
    assert np.allclose(img[..., 2], 7) and np.allclose(img[..., 3], 1)


@pytest.mark.parametrize("crop", [True, False])
def test_border_window_and_offset(tmp_path, synthetic_core, crop):
    s = _scene(40, 30)
    s.render.use_border = True
    s.render.use_crop_to_border = crop
    s.render.border_min_x, s.render.border_max_x = 0.1, 0.6
    s.render.border_min_y, s.render.border_max_y = 0.2, 0.5  # y from the bottom
    img = h.render_exr(tmp_path / "border.exr")
    x0, x1 = int(0.1 * 40), int(0.6 * 40)
    yb0, yb1 = int(0.2 * 30), int(0.5 * 30)
    top0, top1 = 30 - yb1, 30 - yb0  # rows from the top
    if crop:
        assert img.shape == (yb1 - yb0, x1 - x0, 4)
        ys, xs = np.mgrid[top0:top1, x0:x1]
        assert np.allclose(img[..., 0], xs + 0.5) and np.allclose(img[..., 1], ys + 0.5)
    else:
        assert img.shape == (30, 40, 4)
        ys, xs = np.mgrid[0:30, 0:40]
        inside = (xs >= x0) & (xs < x1) & (ys >= top0) & (ys < top1)
        assert np.allclose(img[inside, 0], xs[inside] + 0.5)
        assert np.allclose(img[inside, 1], ys[inside] + 0.5)
        assert np.allclose(img[~inside, :3], 0)


def test_resolution_percentage(tmp_path, synthetic_core):
    s = _scene(80, 60)
    s.render.resolution_percentage = 50
    img = h.render_exr(tmp_path / "half.exr")
    assert img.shape == (30, 40, 4)


# --------------------------------------------------------------------------- real renders

def test_real_render_orientation(tmp_path):
    """An emitter in the upper-left of the view shows up in the upper-left of the file."""
    h.camera(location=(0, 0, 5))
    h.plane("Floor", size=20, material=h.diffuse("Grey", (0.5, 0.5, 0.5)))
    lamp = h.plane("Lamp", size=1.0, location=(-1.2, 0.8, 0.5), material=h.emission(strength=5.0))
    assert lamp
    h.setup_render(48, 36, samples=2, max_depth=1)
    img = h.render_exr(tmp_path / "orient.exr")
    lum = img[..., :3].mean(axis=2)
    ys, xs = np.unravel_index(np.argmax(lum), lum.shape)
    assert xs < 24 and ys < 18, (xs, ys)
    assert lum.max() == pytest.approx(5.0, rel=1e-3)  # directly seen emitter = colour·strength


def test_no_camera_raises_clear_error(tmp_path):
    h.plane()
    h.light("POINT")
    s = h.setup_render()
    s.camera = None
    with pytest.raises(RuntimeError, match="(?i)camera"):
        h.render_exr(tmp_path / "nocam.exr")
    assert not (tmp_path / "nocam.exr").exists()


def test_core_failure_is_reported_as_error(tmp_path, monkeypatch):
    def boom(*args, **kwargs):
        raise ValueError("synthetic core failure")

    monkeypatch.setattr(ercuts_core, "render", boom)
    _scene()
    with pytest.raises(RuntimeError, match="Ercuts: ValueError: synthetic core failure"):
        h.render_exr(tmp_path / "boom.exr")
    assert not (tmp_path / "boom.exr").exists()


def test_missing_dependency_message(tmp_path, monkeypatch):
    def missing(*args, **kwargs):
        raise ModuleNotFoundError("No module named 'embreex'", name="embreex")

    monkeypatch.setattr(ercuts_core, "render", missing)
    _scene()
    with pytest.raises(RuntimeError, match="cannot load the Ercuts core .* embreex"):
        h.render_exr(tmp_path / "nodeps.exr")


def test_scene_error_message_is_passed_through(tmp_path, monkeypatch):
    def reject(*args, **kwargs):
        raise ercuts_core.SceneError("Camera focal length 0 mm must be > 0")

    monkeypatch.setattr(ercuts_core, "render", reject)
    _scene()
    with pytest.raises(RuntimeError, match=r"Error: Ercuts: Camera focal length 0 mm must be > 0"):
        h.render_exr(tmp_path / "rejected.exr")


def test_no_lights_renders_black_with_warning(tmp_path):
    h.camera()
    h.plane(size=4, material=h.diffuse())
    h.setup_render(32, 24, samples=2)
    img = h.render_exr(tmp_path / "dark.exr")
    assert np.allclose(img[..., :3], 0) and np.allclose(img[..., 3], 1)
    warnings = engine_module.last_render["warnings"]
    assert any("no lights" in w.lower() for w in warnings), warnings


def test_material_warning_reported_once(tmp_path):
    h.camera()
    mat = h.node_material("Shiny", "ShaderNodeBsdfToon")   # unsupported: one warning
    h.plane(size=4, material=mat)
    h.plane("B", size=1, material=mat, location=(0, 0, 0.5))
    h.light("POINT")
    h.setup_render(32, 24, samples=1)
    h.render_exr(tmp_path / "warn.exr")
    warnings = engine_module.last_render["warnings"]
    assert sum("'Shiny'" in w for w in warnings) == 1


def test_progress_and_cancel(tmp_path, monkeypatch, interactive):
    """The core's progress callback polls for cancel; a cancel keeps the partial image.

    RNA methods (test_break, update_progress) cannot be patched on the instance, so the
    test stands in for the engine's Python hooks around them.
    """
    calls = {"progress": [], "polls": 0}
    progress = ErcutsRenderEngine._progress

    def spy(self, fraction, message):
        calls["progress"].append((fraction, message))
        return progress(self, fraction, message)

    def should_stop(self):
        calls["polls"] += 1
        return calls["polls"] >= 2  # cancel on the second poll

    monkeypatch.setattr(ErcutsRenderEngine, "_progress", spy)
    monkeypatch.setattr(ErcutsRenderEngine, "_should_stop", should_stop)
    _scene(64, 48)
    s = bpy.context.scene
    s.ercuts.samples = 200
    s.ercuts.batch_rays = 1024  # several batches per pass → several polls
    t0 = time.monotonic()
    img = h.render_exr(tmp_path / "cancel.exr")
    assert time.monotonic() - t0 < 20
    assert engine_module.last_render["cancelled"] is True, (calls, engine_module.last_render)
    assert img[..., :3].max() > 0  # the partial image is kept
    assert len(calls["progress"]) == 2 and calls["polls"] == 2
    fractions = [f for f, _ in calls["progress"]]
    assert 0 < fractions[0] <= fractions[1] < 0.05
    assert all(isinstance(m, str) and m for _, m in calls["progress"])


def test_progress_is_polled_often(tmp_path, monkeypatch):
    """test_break is polled at least once a second while the core renders."""
    stamps = []
    monkeypatch.setattr(ErcutsRenderEngine, "_should_stop",
                        lambda self: stamps.append(time.monotonic()) or False)
    _scene(96, 72)
    s = bpy.context.scene
    s.ercuts.samples = 24
    h.render_exr(tmp_path / "polled.exr")
    assert len(stamps) >= 2
    assert np.max(np.diff(stamps)) < 1.0


def test_time_limit_covers_whole_render(tmp_path):
    _scene(64, 48)
    s = bpy.context.scene
    s.ercuts.samples = 100000
    s.ercuts.time_limit = 2.0
    t0 = time.monotonic()
    img = h.render_exr(tmp_path / "limited.exr")
    elapsed = time.monotonic() - t0
    info = engine_module.last_render
    assert info["cancelled"] is True
    assert 0 < info["settings"]["time_limit"] < 2.0  # the core got what export left over
    assert info["total_seconds"] < 2.0 + 0.5, info
    assert elapsed < 2.0 + 2.0  # Blender's own overhead (file write) on top
    assert img[..., :3].max() > 0


def test_view_layers_each_rendered(tmp_path, monkeypatch):
    """render() runs once per enabled view layer and writes into that layer's result."""
    from addon import compat

    written = []
    write = framebuffer.write_image

    def spy(engine, render, image, window, layer_name, pass_name="Combined"):
        result = engine.begin_result(0, 0, 2, 2, layer=layer_name)
        written.append((layer_name, [layer.name for layer in result.layers]))
        engine.end_result(result, cancel=True)
        return write(engine, render, image, window, layer_name, pass_name)

    monkeypatch.setattr(framebuffer, "write_image", spy)
    _scene(32, 24)
    s = bpy.context.scene
    s.view_layers.new("Second")
    compat.set_multilayer_exr(s.render.image_settings)
    s.render.filepath = str(tmp_path / "layers.exr")
    s.render.use_file_extension = False
    assert bpy.ops.render.render(write_still=True) == {"FINISHED"}
    assert written == [("ViewLayer", ["ViewLayer"]), ("Second", ["Second"])]
    assert (tmp_path / "layers.exr").stat().st_size > 0
