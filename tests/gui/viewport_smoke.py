"""Runs inside a windowed Blender (under Xvfb, software OpenGL): the Rendered viewport.

Started by tests/test_viewport_gui.py as
``blender --factory-startup <cornell_box.blend> --python tests/gui/viewport_smoke.py -- <out_dir>``
with the repository and the environment's site-packages on PYTHONPATH. For three views —
the scene camera (camera view), a free perspective view from the camera's position turned
by 12°, and a free orthographic view along the camera's axis — the 3D view is
screenshotted twice: in Solid shading on a black background (Blender's own drawing of the
geometry) and, once its ``viewport_samples`` = 4 samples are done, in Rendered shading
with Ercuts. Overlays, gizmos, header and toolbar are off. Per view the summary
(``<out_dir>/summary.json``) holds the geometry masks' agreement (intersection over union
of the non-black pixels of both screenshots) and pixel counts of the red and green walls;
the test judges them.
"""
import json
import math
import os
import sys
import time

import bpy
import numpy as np
from mathutils import Euler, Vector

import addon
from addon import viewport

#: Longest wait for a Rendered view to finish its samples [s].
MAX_SECONDS = float(os.environ.get("ERCUTS_GUI_MAX_SECONDS", "120"))
OUT = sys.argv[sys.argv.index("--") + 1]
VIEWS = ("camera", "turned", "ortho")
#: Free orthographic view: the view distance [m] that makes the box fill most of it.
ORTHO_DISTANCE = 3.0
state = {"queue": [], "t0": 0.0, "area": None, "summary": {}, "solid": None}


def pixels(path):
    img = bpy.data.images.load(path)
    w, h = img.size
    px = np.empty(w * h * 4, np.float32)
    img.pixels.foreach_get(px)
    bpy.data.images.remove(img)
    return px.reshape(h, w, 4)[..., :3]


def set_view(name, space):
    rv3d = space.region_3d
    if name == "camera":
        rv3d.view_perspective = "CAMERA"
        return
    cam = bpy.context.scene.camera.matrix_world
    rotation = cam.to_quaternion()
    if name == "turned":        # about the world Z axis (an orthographic view turned like this
        rotation.rotate(Euler((0.0, 0.0, math.radians(12.0))))  # would see a wall's dark outside)
    rv3d.view_perspective = "PERSP" if name == "turned" else "ORTHO"
    if name == "ortho":
        rv3d.view_distance = ORTHO_DISTANCE        # sets the orthographic zoom: fill the view
    rv3d.view_rotation = rotation
    rv3d.view_location = cam.translation + rotation @ Vector((0.0, 0.0, -rv3d.view_distance))


def shot(win, screen, area, path):
    with bpy.context.temp_override(window=win, screen=screen, area=area):
        bpy.ops.screen.screenshot_area(filepath=path)
    return pixels(path)


def summarise(solid, rendered):
    geometry = solid.max(axis=2) > 0.02
    lit = rendered.max(axis=2) > 0.02
    r, g, b = rendered[..., 0], rendered[..., 1], rendered[..., 2]
    union = int((geometry | lit).sum())
    return dict(iou=float((geometry & lit).sum() / max(union, 1)), geometry=int(geometry.sum()),
                lit=int(lit.sum()), red=int(((r > 0.15) & (r > 2.5 * g) & (r > 2.5 * b)).sum()),
                green=int(((g > 0.15) & (g > 2.5 * r) & (g > 2.5 * b)).sum()))


def tick():
    win = bpy.context.window_manager.windows[0]
    screen = win.screen
    if state["area"] is None:
        bpy.context.scene.render.engine = "ERCUTS"
        bpy.context.scene.ercuts.viewport_samples = 4
        state["area"] = next(a for a in screen.areas if a.type == "VIEW_3D")
        space = state["area"].spaces.active
        space.overlay.show_overlays = False         # only the engine's image on screen:
        space.show_gizmo = False                    # no grid, gizmos, header or toolbar
        space.show_region_header = space.show_region_toolbar = False
        space.show_region_tool_header = False
        space.shading.background_type = "VIEWPORT"
        space.shading.background_color = (0.0, 0.0, 0.0)
        state["queue"] = [(v, phase) for v in VIEWS for phase in ("solid", "rendered")]
        state["t0"] = time.time()
    area, space = state["area"], state["area"].spaces.active
    area.tag_redraw()
    waited = time.time() - state["t0"]
    if space.shading.type == "RENDERED":
        rendering = waited < 1.0 or any(s.running for s in viewport.SESSIONS)
        if rendering and waited < MAX_SECONDS:
            return 0.25                             # until the viewport's samples are done
    elif waited < 1.0:
        return 0.25
    if state["t0"] > 0 and state.get("current"):
        view, phase = state["current"]
        img = shot(win, screen, area, os.path.join(OUT, f"{view}_{phase}.png"))
        if phase == "solid":
            state["solid"] = img
        else:
            state["summary"][view] = summarise(state["solid"], img)
            state["summary"][view]["seconds"] = time.time() - state["t0"]
            print("ERCUTS_GUI", view, state["summary"][view], flush=True)
    if not state["queue"]:
        with open(os.path.join(OUT, "summary.json"), "w") as f:
            json.dump(state["summary"], f)
        bpy.ops.wm.quit_blender()
        return None
    view, phase = state["current"] = state["queue"].pop(0)
    set_view(view, space)
    space.shading.type = "SOLID" if phase == "solid" else "RENDERED"
    state["t0"] = time.time()
    return 0.25


addon.register()
bpy.app.timers.register(tick, first_interval=1.0)
