"""Rendered viewport mode (addon/viewport.py) with real bpy.

Blender draws viewports only with a GPU and a window, which neither the bpy module nor
``blender -b`` has; ``view_update``/``view_draw`` are therefore driven here with a
stand-in for the engine's viewport methods (tag_redraw, update_stats, pixel size) and for
the region (width, height and real view/window matrices, taken from a Blender camera with
``calc_matrix_camera``). The camera maths, the worker thread, restarts and the image are
the add-on's real code on real exported scenes.
"""
from __future__ import annotations

import types

import bpy
import numpy as np
import pytest

import blender_helpers as h
from addon import viewport
from test_export import CAMERA_CASES, camera_case


def _matrices(ob, width, height):
    """(view_matrix, window_matrix) of a viewport looking through ``ob`` (camera view)."""
    depsgraph = bpy.context.evaluated_depsgraph_get()
    window = ob.calc_matrix_camera(depsgraph, x=width, y=height)
    return ob.matrix_world.inverted(), window


SQUARE_PIXEL_CASES = [c for c in CAMERA_CASES if "aspect" not in c]


@pytest.mark.parametrize("case", SQUARE_PIXEL_CASES, ids=[str(i) for i in range(len(SQUARE_PIXEL_CASES))])
def test_region_camera_gives_the_rays_of_the_exported_camera(case):
    """The region camera built from Blender's projection matrix shoots the exported
    camera's rays (perspective: same origin and direction to 1e-6, mathutils being float32;
    orthographic: same direction and the same line, the origin moved to the near plane)."""
    from ercuts_core.camera import Camera

    ob = camera_case(case)
    exported = h.export().description.camera
    W, H = exported.width, exported.height
    view, window = _matrices(ob, W, H)
    region = viewport.region_camera(view, window, W, H)
    rng = np.random.default_rng(3)
    raster = np.c_[rng.uniform(0, W, 200), rng.uniform(0, H, 200)]
    o_e, d_e = Camera(exported).generate_rays(raster)
    o_r, d_r = Camera(region).generate_rays(raster)
    assert np.allclose(d_r, d_e, atol=1e-6)
    if "ortho" in case:
        offset = o_r - o_e
        along = offset @ d_e[0]
        assert np.allclose(offset, along[:, None] * d_e, atol=1e-6)
        # The camera's near plane, as far as float32 P[2][3]+1 resolves it (clip_end/clip_start
        # = 1000 amplifies its rounding to ~5e-5 m).
        assert np.allclose(along, ob.data.clip_start, atol=1e-3)
    else:
        assert np.allclose(o_r, o_e, atol=1e-6)


def test_region_camera_of_a_free_orthographic_view_starts_behind_the_pivot():
    """A free orthographic viewport's near plane lies behind its pivot (n < 0): the rays
    start there, so geometry between the pivot and the viewer is not lost."""
    from ercuts_core.camera import Camera
    from mathutils import Matrix

    n, f, half = -50.0, 50.0, 4.0           # Blender's ortho viewport: near = −far
    window = Matrix(((1 / half, 0, 0, 0), (0, 1 / half, 0, 0),
                     (0, 0, -2 / (f - n), -(f + n) / (f - n)), (0, 0, 0, 1)))
    view = Matrix.Translation((0, 0, -10))  # world → view: the view sits at z = 10, looking down
    cam = Camera(viewport.region_camera(view, window, 32, 32))
    o, d = cam.generate_rays(np.array([[16.0, 16.0]]))
    assert np.allclose(d, [[0, 0, -1]]) and np.allclose(o, [[0, 0, 10 - n]])
    assert cam.xmax - cam.xmin == pytest.approx(2 * half)


def test_camera_frame_and_border_in_region_fractions():
    ob = camera_case(dict(res=(64, 32), fit="AUTO", shift=(0.1, 0.05)))
    view, window = _matrices(ob, 64, 32)
    world = np.array(ob.matrix_world)
    corners = np.array([list(v) for v in ob.data.view_frame(scene=bpy.context.scene)])
    corners = corners @ world[:3, :3].T + world[:3, 3]
    frame = viewport.frame_in_region(window @ view, corners)
    assert np.allclose(frame, (0, 0, 1, 1), atol=1e-6)
    # The region shows the camera frame at half size around its centre (zoomed out).
    from mathutils import Matrix
    zoomed = Matrix.Diagonal((0.5, 0.5, 1.0, 1.0)) @ window
    frame = viewport.frame_in_region(zoomed @ view, corners)
    assert np.allclose(frame, (0.25, 0.25, 0.75, 0.75), atol=1e-6)
    assert np.allclose(viewport.camera_border(frame, (0.5, 0.0, 1.0, 0.5)), (0.5, 0.25, 0.75, 0.5))
    assert viewport.camera_border((1.2, 0.0, 2.0, 1.0), (0.0, 0.0, 1.0, 1.0)) is None


def test_draw_pixels_are_bottom_up_finite_and_fit_a_half_float_texture():
    image = np.zeros((2, 3, 4), np.float32)
    image[0, 0] = (np.nan, np.inf, 1e9, 1.0)      # top-left of the window
    image[1, 2] = (0.5, 0.25, 0.125, 1.0)
    out = viewport.draw_pixels(image, (1, 0, 3, 2), (5, 4))
    assert out.shape == (4, 5, 4) and out.dtype == np.float32
    assert np.isfinite(out).all() and out.max() <= viewport.HALF_MAX
    assert np.array_equal(out[3, 1], (0.0, viewport.HALF_MAX, viewport.HALF_MAX, 1.0))  # top row
    assert np.array_equal(out[2, 3], (0.5, 0.25, 0.125, 1.0))
    assert out[:2].max() == 0 and out[:, 0].max() == 0                  # outside the window


# --------------------------------------------------------------------------- sessions

def _scene(width=32, height=24):
    s = h.setup_render(width, height, samples=4, integrator="PATH", max_depth=3)
    h.box("Room", size=(4, 4, 3), location=(0, 0, 1.5), material=h.diffuse("Walls"), inward=True)
    h.box("Block", size=(1, 1, 1), location=(0.5, 0.5, 0.5), material=h.diffuse("Block"))
    cam = h.camera(location=(0, -1.8, 1.5), target=(0, 0, 0.8))
    h.light("POINT", location=(0, 0, 2.5), energy=100.0)
    s.ercuts.viewport_samples = 4
    bpy.context.view_layer.update()
    return s, cam


def _render_direct(desc, settings):
    import ercuts_core
    return ercuts_core.render(desc, settings)


def test_session_renders_in_a_thread_what_the_core_renders():
    s, _ = _scene()
    desc = h.export().description
    settings = viewport.viewport_settings(s)
    assert settings.integrator == "PATH" and settings.samples == 4 and settings.time_limit == 0
    session = viewport.ViewportSession()
    session.start("k", desc, settings)
    assert session.join(60) and not session.running and session.error is None
    want = _render_direct(desc, settings)
    assert np.array_equal(session.frame.image, want.image)
    assert session.frame.samples == 4 and session.status.startswith("Done | 4 samples")


def test_restart_stops_the_old_render_without_waiting_and_drops_its_images():
    s, _ = _scene()
    desc = h.export().description
    long = viewport.viewport_settings(s).replace(samples=100000)
    short = viewport.viewport_settings(s).replace(samples=2, seed=9)
    session = viewport.ViewportSession()
    session.start("long", desc, long)
    first = session._thread
    session.start("short", desc, short)        # returns at once: the old thread is only told
    assert session.key == "short"
    first.join(10)
    assert not first.is_alive()                # it stopped at its next progress poll
    assert session.join(60) and session.error is None
    assert np.array_equal(session.frame.image, _render_direct(desc, short).image)


def test_a_failing_render_becomes_the_status_not_an_exception():
    def broken(desc, settings, progress=None, preview=None):
        raise ZeroDivisionError("simulated core failure")

    s, _ = _scene(8, 6)
    session = viewport.ViewportSession(render_fn=broken)
    session.start("k", h.export().description, viewport.viewport_settings(s))
    assert session.join(10)
    assert not session.running and session.error == "ZeroDivisionError: simulated core failure"


# --------------------------------------------------------------------------- engine hooks

class ViewportEngine:
    """Stand-in for a RenderEngine's viewport services (no GPU or window headless)."""

    def __init__(self, pixel_size=1):
        self.redraws, self.stats, self.pixel_size = 0, [], pixel_size

    def tag_redraw(self):
        self.redraws += 1

    def update_stats(self, engine, text):
        self.stats.append(text)

    def get_preview_pixel_size(self, scene):
        return self.pixel_size


def _context(view, window, width, height, perspective="CAMERA", render_border=None):
    space = types.SimpleNamespace(use_render_border=render_border is not None)
    if render_border is not None:
        (space.render_border_min_x, space.render_border_min_y,
         space.render_border_max_x, space.render_border_max_y) = render_border
    return types.SimpleNamespace(
        region=types.SimpleNamespace(width=width, height=height),
        region_data=types.SimpleNamespace(view_perspective=perspective, view_matrix=view,
                                          window_matrix=window, perspective_matrix=window @ view),
        space_data=space)


def test_camera_view_shows_what_a_final_render_of_the_camera_shows(tmp_path):
    """view_update + view_draw in camera view render the camera's image: the same pixels
    as a final PATH render at the same samples and seed (the rays agree to 1e-6)."""
    s, cam = _scene()
    engine, depsgraph = ViewportEngine(), bpy.context.evaluated_depsgraph_get()
    context = _context(*_matrices(cam, 32, 24), 32, 24)
    viewport.view_update(engine, context, depsgraph)
    viewport.view_draw(engine, context, depsgraph)
    session = engine._viewport_session
    assert session.join(60) and session.error is None
    final = h.render_exr(tmp_path / "final.exr")                   # top row first
    got = session.frame.image
    assert got.shape == final.shape
    assert np.allclose(got, final, rtol=1e-3, atol=1e-5)
    viewport.view_draw(engine, context, depsgraph)                  # done: no more redraws
    assert engine.stats[-1].startswith("Done | 4 samples")


def test_view_changes_edits_and_pixel_size_restart_the_render_and_nothing_else_does():
    s, cam = _scene()
    engine, depsgraph = ViewportEngine(), bpy.context.evaluated_depsgraph_get()
    view, window = _matrices(cam, 32, 24)
    context = _context(view, window, 32, 24)
    viewport.view_update(engine, context, depsgraph)
    viewport.view_draw(engine, context, depsgraph)
    session = engine._viewport_session
    first = session._thread
    viewport.view_draw(engine, context, depsgraph)                  # a plain redraw
    assert session._thread is first
    from mathutils import Matrix
    orbit = Matrix.Rotation(0.1, 4, "Z") @ view
    viewport.view_draw(engine, _context(orbit, window, 32, 24), depsgraph)
    second = session._thread
    assert second is not first
    bpy.data.objects["Block"].location.x += 0.2                     # an edit → view_update
    bpy.context.view_layer.update()
    viewport.view_update(engine, context, depsgraph)
    viewport.view_draw(engine, _context(orbit, window, 32, 24), depsgraph)
    assert session._thread is not second
    engine.pixel_size = 2
    viewport.view_draw(engine, _context(orbit, window, 32, 24), depsgraph)
    assert session.join(60) and session.frame.size == (16, 12)
    assert engine.redraws >= 1


def test_viewport_render_region_renders_only_the_border():
    s, cam = _scene()
    engine, depsgraph = ViewportEngine(), bpy.context.evaluated_depsgraph_get()
    context = _context(*_matrices(cam, 32, 24), 32, 24, perspective="PERSP",
                       render_border=(0.25, 0.5, 0.75, 1.0))
    viewport.view_update(engine, context, depsgraph)
    viewport.view_draw(engine, context, depsgraph)
    session = engine._viewport_session
    assert session.join(60)
    assert session.frame.window == (8, 0, 16, 12) and session.frame.image.shape == (12, 16, 4)
    pixels = viewport.draw_pixels(session.frame.image, session.frame.window, session.frame.size)
    assert pixels[:12].max() == 0 and pixels[12:, 8:24, 3].min() > 0    # only the top middle


def test_camera_view_uses_the_scene_border_inside_the_camera_frame():
    s, cam = _scene()
    s.render.use_border = True
    s.render.border_min_x, s.render.border_max_x = 0.0, 0.5
    s.render.border_min_y, s.render.border_max_y = 0.0, 1.0
    engine, depsgraph = ViewportEngine(), bpy.context.evaluated_depsgraph_get()
    view, window = _matrices(cam, 32, 24)
    from mathutils import Matrix
    zoomed = Matrix.Diagonal((0.5, 0.5, 1.0, 1.0)) @ window         # frame = middle half
    context = _context(view, zoomed, 32, 24)
    assert np.allclose(viewport.viewport_border(context, s), (0.25, 0.25, 0.5, 0.75), atol=1e-6)
    s.render.border_min_x, s.render.border_max_x = 0.0, 0.1
    pan = Matrix.Translation((1.5, 0, 0)) @ zoomed                  # frame pushed to the right
    context = _context(view, pan, 32, 24)
    assert viewport.viewport_border(context, s) == (0.0, 0.0, 0.0, 0.0)   # border off-screen
    viewport.view_update(engine, context, depsgraph)
    viewport.view_draw(engine, context, depsgraph)
    assert engine._viewport_session.frame is None and not engine._viewport_session.running


def test_export_errors_are_the_viewport_status(monkeypatch):
    from addon import export

    def failing(*args, **kwargs):
        raise export.ExportError("object 'Broken': simulated export failure")

    _scene(8, 6)
    monkeypatch.setattr(export, "export_scene", failing)
    engine, depsgraph = ViewportEngine(), bpy.context.evaluated_depsgraph_get()
    cam = bpy.context.scene.camera
    context = _context(*_matrices(cam, 8, 6), 8, 6)
    viewport.view_update(engine, context, depsgraph)
    viewport.view_draw(engine, context, depsgraph)
    assert engine.stats[-1] == "Error: object 'Broken': simulated export failure"
    assert getattr(engine, "_viewport_session").frame is None


def test_a_large_viewport_shows_a_quick_coarse_image_first():
    """Above COARSE_PIXELS the first image is one sample at reduced resolution; the full
    resolution replaces it (the final frame is the full render)."""
    import ercuts_core

    s, _ = _scene(256, 192)                                   # 49 152 px → factor 2
    desc = h.export().description
    calls, frames = [], []

    def spy(d, settings, progress=None, preview=None):
        calls.append((d.camera.width, d.camera.height, settings.samples))
        return ercuts_core.render(d, settings, progress=progress, preview=preview)

    session = viewport.ViewportSession(render_fn=spy)
    publish = session._publish
    session._publish = lambda g, frame, **kw: (frames.append(frame.size), publish(g, frame, **kw))
    session.start("k", desc, viewport.viewport_settings(s))
    assert session.join(120) and session.error is None
    assert calls == [(128, 96, 1), (256, 192, 4)]
    assert frames[0] == (128, 96) and frames[-1] == (256, 192)
    assert session.frame.size == (256, 192) and session.frame.samples == 4


def test_stop_all_ends_every_viewport_render():
    """Unregistering the add-on (and Blender quitting, through atexit) stops the renders."""
    s, _ = _scene()
    desc = h.export().description
    sessions = [viewport.ViewportSession() for _ in range(2)]
    for session in sessions:
        session.start("long", desc, viewport.viewport_settings(s).replace(samples=100000))
    viewport.stop_all(timeout=10)
    assert all(not session._thread.is_alive() for session in sessions)
    assert all(session.frame is None or session.frame.samples < 100000 for session in sessions)
