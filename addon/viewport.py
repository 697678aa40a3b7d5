"""Rendered viewport mode: export on the main thread, render in a worker, draw the latest image.

Blender calls the engine's ``view_update`` when the scene changes and ``view_draw`` on every
redraw of a viewport in *Rendered* shading (shared docs ``blender.md`` §1.5):

* ``view_update`` exports the evaluated scene (:func:`addon.export.export_scene`, main
  thread, the only bpy access) into a plain description and bumps its version;
* ``view_draw`` derives the core's camera from the region (:func:`region_camera`: the view
  and window matrices, so perspective, orthographic and camera views, zoom and offset in
  camera view all follow from the same projection), the render border
  (:func:`viewport_border`) and the pixel size; when the scene version or any of these
  changed it restarts the render, then uploads and draws the newest image it has, and
  asks for another redraw while the render is still refining;
* :class:`ViewportSession` runs ``ercuts_core.render`` in a daemon thread on that plain
  data (no bpy there): a quick one-sample image at reduced resolution first for a large
  region, then PATH or BDPT (``viewport_integrator``), ``viewport_samples`` passes, each
  shown as it completes (the core's ``preview`` callback). A restart signals the old
  thread to stop (it returns at its next progress poll, within a batch) and never waits
  for it, so editing and orbiting do not block the UI; images of a superseded render are
  dropped.

Errors (an export error, a failing render) become the viewport's status text and a
console line, never a traceback in the UI. Drawing imports ``gpu`` lazily (it is missing
in background mode) and uploads scene-linear RGBA; the display transform is Blender's.
"""
from __future__ import annotations

import atexit
import dataclasses
import threading
import time
import traceback
import weakref
from dataclasses import dataclass

import numpy as np

from .errors import error_message

#: Largest value an RGBA16F texture holds.
HALF_MAX = 65000.0
#: ``viewport_border`` when the border lies wholly outside the region: nothing to render.
EMPTY_BORDER = (0.0, 0.0, 0.0, 0.0)
#: Pixels of the quick first image of a large viewport (one sample, then full resolution).
COARSE_PIXELS = 16384


# --------------------------------------------------------------------------- camera

def _matrix(m) -> np.ndarray:
    return np.array([list(row) for row in m], np.float64).reshape(4, 4)


def region_camera(view_matrix, window_matrix, width: int, height: int,
                  origin=(0.0, 0.0, 0.0), border=None):
    """The core's ``CameraDesc`` for a viewport region.

    Reads an OpenGL-style projection ``P = window_matrix`` (column vectors, camera looking
    down −Z). Perspective (P[3][2] = −1): at unit distance the frustum spans
    ``2/P[0][0]`` horizontally and is centred at (P[0][2]/P[0][0], P[1][2]/P[1][1]), so with
    a horizontal sensor fit ``lens/sensor_width = P[0][0]/2`` and the lens shift in units of
    the width is ``shift_x = P[0][2]/2``, ``shift_y = P[1][2]·P[0][0]/(2·P[1][1])``.
    Orthographic (P[3][3] = 1): width ``ortho_scale = 2/P[0][0]``, centre
    (−P[0][3]/P[0][0], −P[1][3]/P[1][1]); the camera moves to the near plane
    ``n = (P[2][3]+1)/P[2][2]`` (behind the view's pivot in a free viewport), because the core
    starts orthographic rays in the camera plane.

    Args:
        view_matrix: (4, 4) world → view (rigid), e.g. ``region_data.view_matrix``.
        window_matrix: (4, 4) projection, e.g. ``region_data.window_matrix``.
        width, height: render size in pixels (the region divided by the pixel size).
        origin: (3,) [m] the description's origin in Blender's world (export stats 'origin').
        border: optional (xmin, ymin, xmax, ymax) region fractions, y from the bottom.
    """
    from ercuts_core.description import CameraDesc

    P = _matrix(window_matrix)
    world_from_view = np.linalg.inv(_matrix(view_matrix))
    ortho = abs(P[3][3] - 1.0) < 1e-9 and abs(P[3][2]) < 1e-9
    sensor = 36.0
    if ortho:
        near = (P[2][3] + 1.0) / P[2][2]
        world_from_view = world_from_view @ _translation((0.0, 0.0, -near))
        shift_x = -P[0][3] / 2.0
        shift_y = -P[1][3] * P[0][0] / (2.0 * P[1][1])
        extra = dict(projection="ORTHO", ortho_scale=2.0 / P[0][0])
    else:
        shift_x = P[0][2] / 2.0
        shift_y = P[1][2] * P[0][0] / (2.0 * P[1][1])
        extra = dict(projection="PERSP", lens=P[0][0] * sensor / 2.0)
    world_from_view[:3, 3] -= np.asarray(origin, np.float64)
    use_border = border is not None
    return CameraDesc(
        world_from_camera=world_from_view, width=int(width), height=int(height),
        sensor_width=sensor, sensor_height=sensor, sensor_fit="HORIZONTAL",
        shift_x=float(shift_x), shift_y=float(shift_y),
        border=tuple(border) if use_border else (0.0, 0.0, 1.0, 1.0), use_border=use_border,
        **extra)


def _translation(t) -> np.ndarray:
    m = np.eye(4)
    m[:3, 3] = t
    return m


def frame_in_region(perspective_matrix, corners_world) -> tuple[float, float, float, float]:
    """Bounding box (xmin, ymin, xmax, ymax) in region fractions of world points.

    Args:
        perspective_matrix: (4, 4) world → clip (``region_data.perspective_matrix``).
        corners_world: (N, 3) [m], e.g. the camera's ``view_frame`` corners in world space.
    """
    pts = np.c_[np.asarray(corners_world, np.float64), np.ones(len(corners_world))]
    clip = pts @ _matrix(perspective_matrix).T
    ndc = clip[:, :2] / clip[:, 3:4]
    lo, hi = (ndc.min(axis=0) + 1.0) / 2.0, (ndc.max(axis=0) + 1.0) / 2.0
    return float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1])


def camera_border(frame, border) -> tuple[float, float, float, float] | None:
    """The render border (fractions of the camera frame) in region fractions, clipped to
    the region; None when nothing of it is inside."""
    fx0, fy0, fx1, fy1 = frame
    bx0, by0, bx1, by1 = border
    box = (fx0 + bx0 * (fx1 - fx0), fy0 + by0 * (fy1 - fy0),
           fx0 + bx1 * (fx1 - fx0), fy0 + by1 * (fy1 - fy0))
    x0, y0 = max(box[0], 0.0), max(box[1], 0.0)
    x1, y1 = min(box[2], 1.0), min(box[3], 1.0)
    return (x0, y0, x1, y1) if x1 > x0 and y1 > y0 else None


def viewport_border(context, scene):
    """The viewport's render border in region fractions, or None for the whole region.

    In camera view it is the scene's render border (Output properties) inside the camera
    frame; otherwise the viewport's own *Render Region* (``space.use_render_border``)."""
    rv3d, space = context.region_data, context.space_data
    if rv3d.view_perspective == "CAMERA":
        render = scene.render
        cam = scene.camera
        if not render.use_border or cam is None:
            return None
        world = _matrix(cam.matrix_world)
        local = np.array([list(v) for v in cam.data.view_frame(scene=scene)], np.float64)
        corners = local @ world[:3, :3].T + world[:3, 3]
        frame = frame_in_region(rv3d.perspective_matrix, corners)
        border = camera_border(frame, (render.border_min_x, render.border_min_y,
                                       render.border_max_x, render.border_max_y))
        return border if border is not None else EMPTY_BORDER
    if getattr(space, "use_render_border", False):
        return (space.render_border_min_x, space.render_border_min_y,
                space.render_border_max_x, space.render_border_max_y)
    return None


# --------------------------------------------------------------------------- pixels

def draw_pixels(image: np.ndarray, window, size: tuple[int, int]) -> np.ndarray:
    """The texture for ``view_draw``: (height, width, 4) float32, bottom row first.

    ``image`` is the core's (h, w, 4) window image (top row first, scene-linear,
    premultiplied alpha) at ``window`` = (x0, y0, w, h) of a ``size`` = (width, height)
    frame; uncovered pixels are transparent, non-finite values 0, and values are clamped
    to what a half-float texture holds."""
    from .framebuffer import place

    width, height = size
    out = place(np.asarray(image, np.float32), window, height, (0, 0), (width, height))
    out = np.nan_to_num(out, nan=0.0, posinf=HALF_MAX, neginf=0.0)
    return np.clip(out, 0.0, HALF_MAX)


# --------------------------------------------------------------------------- the worker

def _geometry(desc) -> tuple[tuple, tuple]:
    """(window, size) of ``desc``'s image: (x0, y0, w, h) and the frame's (width, height)."""
    from ercuts_core.camera import render_window

    return render_window(desc.camera).rect, (desc.camera.width, desc.camera.height)


@dataclass
class Frame:
    """The newest image of a viewport render (plain data, safe across threads)."""

    image: np.ndarray          # (h, w, 4) float32, the core's convention
    window: tuple              # (x0, y0, w, h) in the frame
    size: tuple                # (width, height) of the frame
    samples: int = 0


#: Every live session (scripts and tests wait on them: ``all(not s.running for s in SESSIONS)``).
SESSIONS: weakref.WeakSet = weakref.WeakSet()


def stop_all(timeout: float = 2.0) -> None:
    """Stop every viewport render and wait up to ``timeout`` seconds for each (add-on
    unregister, Blender quitting: no render thread is left running into shutdown)."""
    sessions = list(SESSIONS)
    for session in sessions:
        session.stop()
    for session in sessions:
        session.join(timeout)


atexit.register(stop_all)


class ViewportSession:
    """One viewport's renders: at most one current render thread; restarts never wait."""

    def __init__(self, render_fn=None):
        SESSIONS.add(self)
        self._render_fn = render_fn
        self._lock = threading.Lock()
        self._generation = 0
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self.key = None
        self.frame: Frame | None = None
        self.status = ""
        self.error: str | None = None
        self.done = True

    # ---- control (main thread)
    def start(self, key, desc, settings) -> None:
        """Render ``desc`` with ``settings`` in a new thread; ``key`` names what it renders."""
        self.stop()
        with self._lock:
            self._generation += 1
            generation, self.key = self._generation, key
            self.error, self.done, self.status = None, False, "Starting"
            self._stop = stop = threading.Event()
        self._thread = threading.Thread(target=self._run, args=(generation, stop, desc, settings),
                                        name="ercuts-viewport", daemon=True)
        self._thread.start()

    def stop(self) -> None:
        """Ask the current render to stop (it returns at its next poll); does not wait."""
        self._stop.set()

    def join(self, timeout: float | None = None) -> bool:
        """Wait for the current thread (tests, shutdown); True when it has ended."""
        thread = self._thread
        if thread is not None:
            thread.join(timeout)
            return not thread.is_alive()
        return True

    @property
    def running(self) -> bool:
        return not self.done

    # ---- the worker thread (no bpy here)
    def _current(self, generation: int) -> bool:
        return generation == self._generation

    def _run(self, generation, stop, desc, settings) -> None:
        render = self._render_fn
        if render is None:
            import ercuts_core
            render = ercuts_core.render
        window, size = _geometry(desc)
        t0 = time.monotonic()

        def progress(fraction, message):
            with self._lock:
                if self._current(generation):
                    self.status = f"{message.split('|')[0].strip()} | {time.monotonic() - t0:.0f} s"
            return not stop.is_set()

        def preview(image):
            self._publish(generation, Frame(np.array(image, np.float32), window, size))

        try:
            self._coarse_pass(generation, stop, desc, settings, render, size)
            result = render(desc, settings, progress=progress, preview=preview)
            frame = Frame(np.asarray(result.image, np.float32), tuple(result.window), size,
                          int(result.stats.get("samples", 0)))
            self._publish(generation, frame, status=(
                f"{'Stopped' if result.cancelled else 'Done'} | {frame.samples} samples | "
                f"{time.monotonic() - t0:.1f} s"), done=True)
        except Exception as exc:  # noqa: BLE001 - shown as the viewport's status, never raised
            traceback.print_exc()
            with self._lock:
                if self._current(generation):
                    self.error, self.status, self.done = f"{type(exc).__name__}: {exc}", "", True

    def _coarse_pass(self, generation, stop, desc, settings, render, size) -> None:
        """One quick sample at about :data:`COARSE_PIXELS` pixels first, so a large viewport
        shows the edited scene within a fraction of a second (stretched until the full
        resolution's first pass replaces it)."""
        width, height = size
        factor = int(np.ceil(np.sqrt(width * height / COARSE_PIXELS)))
        if factor < 2:
            return
        small = desc.replace(camera=dataclasses.replace(
            desc.camera, width=max(width // factor, 1), height=max(height // factor, 1)))
        result = render(small, settings.replace(samples=1), progress=lambda f, m: not stop.is_set())
        if not result.cancelled:
            self._publish(generation, Frame(np.asarray(result.image, np.float32), *_geometry(small)))

    def _publish(self, generation, frame, status=None, done=False) -> None:
        with self._lock:
            if not self._current(generation):
                return                      # a superseded render: drop its image
            self.frame = frame
            if status is not None:
                self.status = status
            self.done = self.done or done


# --------------------------------------------------------------------------- engine hooks

@dataclass
class SceneState:
    """What ``view_update`` exported: the description and its version."""

    description: object = None
    origin: tuple = (0.0, 0.0, 0.0)
    version: int = 0
    error: str | None = None
    #: images kept between exports (:class:`addon.export.images.TextureCollector`)
    texture_cache: dict = dataclasses.field(default_factory=dict)


def viewport_settings(scene):
    """Core settings for the viewport: the scene's, with the viewport integrator and samples,
    no time limit (the viewport keeps refining until the samples are done)."""
    ercuts = scene.ercuts           # viewport_integrator offers PATH and BDPT only (properties.py)
    return ercuts.to_core(seed=ercuts.seed_for_frame(scene.frame_current),
                          integrator=ercuts.viewport_integrator,
                          samples=int(ercuts.viewport_samples), time_limit=0.0)


def view_update(engine, context, depsgraph) -> None:
    """Export the changed scene (main thread); the next ``view_draw`` restarts the render."""
    from . import compat

    state = _state(engine)
    try:
        compat.preload_embreex()
        from .export import export_scene

        exported = export_scene(depsgraph, require_camera=False, texture_cache=state.texture_cache)
        state.description, state.error = exported.description, None
        state.origin = tuple(exported.stats.get("origin", (0.0, 0.0, 0.0)))
        for w in dict.fromkeys(exported.warnings):
            print(f"Ercuts viewport warning: {w}")
    except Exception as exc:  # noqa: BLE001 - an export error is the viewport's status
        state.description, state.error = None, error_message(exc)
        print(f"Ercuts viewport: {state.error}")
        traceback.print_exc()
    state.version += 1
    engine.tag_redraw()


def region_key(context, scene, pixel_size: int):
    """Everything of the region the image depends on: (width, height, matrices, border)."""
    region, rv3d = context.region, context.region_data
    width = max(int(region.width) // max(pixel_size, 1), 1)
    height = max(int(region.height) // max(pixel_size, 1), 1)
    flat = tuple(round(v, 9) for m in (rv3d.view_matrix, rv3d.window_matrix) for row in m for v in row)
    return width, height, flat, viewport_border(context, scene)


def view_draw(engine, context, depsgraph) -> None:
    """Restart the render when the view or the scene changed; draw the newest image."""
    scene = depsgraph.scene
    state, session = _state(engine), _session(engine)
    if state.error is not None:
        engine.update_stats("Ercuts", f"Error: {state.error}")
        return
    if state.description is None:
        return
    region = region_key(context, scene, int(engine.get_preview_pixel_size(scene)))
    settings = viewport_settings(scene)
    key = (state.version, region, settings)
    if key != session.key:
        width, height, _, border = region
        if border == EMPTY_BORDER:
            session.stop()
            session.key, session.frame = key, None
        else:
            rv3d = context.region_data
            camera = region_camera(rv3d.view_matrix, rv3d.window_matrix, width, height,
                                   state.origin, border)
            session.start(key, state.description.replace(camera=camera), settings)
    if session.error is not None:
        engine.update_stats("Ercuts", f"Error: {session.error}")
    else:
        engine.update_stats("Ercuts", session.status)
    frame = session.frame
    if frame is not None:
        _draw(engine, scene, frame, context.region)
    if session.running:
        engine.tag_redraw()                     # keep drawing while the render refines


def _draw(engine, scene, frame: Frame, region) -> None:
    """Draw ``frame`` over the region (GPU context); it is uploaded as an RGBA16F texture
    once, later redraws reuse the texture."""
    import bpy

    if bpy.app.background:                      # no window: nothing to draw on
        return
    import gpu
    from gpu_extras.presets import draw_texture_2d

    cached = getattr(engine, "_viewport_texture", None)
    if cached is None or cached[0] is not frame:
        pixels = draw_pixels(frame.image, frame.window, frame.size)
        h, w = pixels.shape[:2]
        buffer = gpu.types.Buffer("FLOAT", w * h * 4, pixels.ravel())
        cached = engine._viewport_texture = (frame, gpu.types.GPUTexture((w, h), format="RGBA16F",
                                                                         data=buffer))
    gpu.state.blend_set("ALPHA_PREMULT")
    engine.bind_display_space_shader(scene)
    draw_texture_2d(cached[1], (0, 0), region.width, region.height)
    engine.unbind_display_space_shader()
    gpu.state.blend_set("NONE")


def _state(engine) -> SceneState:
    state = getattr(engine, "_viewport_state", None)
    if state is None:
        state = engine._viewport_state = SceneState()
    return state


def _session(engine) -> ViewportSession:
    session = getattr(engine, "_viewport_session", None)
    if session is None:
        session = engine._viewport_session = ViewportSession()
    return session

