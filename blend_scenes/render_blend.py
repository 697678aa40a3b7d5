"""Render a .blend with the Ercuts engine, headless, to a linear EXR and a display PNG.

    .venv/bin/python blend_scenes/render_blend.py blend_scenes/s_corridor.blend -o out/s_corridor
    PYTHONPATH=.venv/lib/python3.11/site-packages:. blender -b --factory-startup \\
        --python blend_scenes/render_blend.py -- blend_scenes/s_corridor.blend -o out/s_corridor

Writes ``<out>.exr`` (scene-linear, 32-bit float) and ``<out>.png`` (through the file's
view transform), and prints the time and the engine's statistics. Options override the
file's ``scene.ercuts`` settings (``--samples``, ``--integrator``, ``--time-limit``, …).
The exit status is non-zero, and no file is written, when the render fails (e.g. no
camera) or is interrupted (Ctrl-C); reaching the time limit is a normal end.
"""
from __future__ import annotations

import argparse
import os
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
if ROOT not in sys.path:
    sys.path.insert(0, ROOT)

import addon  # noqa: E402  (before bpy-dependent imports of the core; see addon.compat)
import bpy  # noqa: E402


def parse(argv):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("blend", help=".blend file to render")
    p.add_argument("-o", "--output", help="output path without extension (default: out/<name>)")
    p.add_argument("--samples", type=int, help="PATH/BDPT samples per pixel")
    p.add_argument("--rough-samples", type=int, help="ERCUTS: rough BDPT samples per pixel per iteration")
    p.add_argument("--iterations", type=int, help="ERCUTS iterations (0 = until the time limit)")
    p.add_argument("--integrator", choices=("ERCUTS", "BDPT", "PATH"))
    p.add_argument("--max-depth", type=int)
    p.add_argument("--time-limit", type=float)
    p.add_argument("--seed", type=int)
    p.add_argument("--resolution", type=int, nargs=2, metavar=("W", "H"))
    p.add_argument("--engine", default="ERCUTS", help="render engine (e.g. CYCLES to compare)")
    return p.parse_args(argv)


def open_blend(path: str, resolution=None):
    """Register the add-on (once), open the .blend at ``path`` and, if given, set its
    ``resolution`` (W, H) at 100 %; returns its scene."""
    if not hasattr(bpy.types.Scene, "ercuts"):
        addon.register()
    bpy.ops.wm.open_mainfile(filepath=os.path.abspath(path))
    scene = bpy.context.scene
    if resolution:
        scene.render.resolution_x, scene.render.resolution_y = resolution
        scene.render.resolution_percentage = 100
    return scene


def main(argv=None) -> int:
    if argv is None:
        argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else sys.argv[1:]
    args = parse(argv)
    scene = open_blend(args.blend, args.resolution)
    scene.render.engine = args.engine
    for key in ("samples", "rough_samples", "iterations", "integrator", "max_depth", "time_limit", "seed"):
        value = getattr(args, key)
        if value is not None:
            setattr(scene.ercuts, key, value)
    name = os.path.splitext(os.path.basename(args.blend))[0]
    out = os.path.abspath(args.output or os.path.join(ROOT, "out", name))
    os.makedirs(os.path.dirname(out), exist_ok=True)

    t0 = time.monotonic()
    try:
        bpy.ops.render.render()
    except RuntimeError as exc:
        print(f"render_blend: {exc}".strip(), file=sys.stderr)
        return 1
    elapsed = time.monotonic() - t0
    result = bpy.data.images["Render Result"]
    ims = scene.render.image_settings
    addon.compat.set_single_layer_exr(ims)
    ims.color_depth = "32"
    result.save_render(out + ".exr", scene=scene)
    ims.file_format = "PNG"
    ims.color_depth = "8"
    result.save_render(out + ".png", scene=scene)

    from addon.engine import last_render

    used = args.engine
    if args.engine == "ERCUTS" and last_render:
        used = f"ERCUTS (integrator {last_render['settings']['integrator']})"
    print(f"render_blend: {args.blend} with {used} in {elapsed:.2f} s -> {out}.exr, {out}.png")
    if args.engine == "ERCUTS" and last_render:
        print(f"render_blend: {last_render['summary']} | export {last_render['export_seconds']:.3f} s")
        for w in last_render["warnings"]:
            print(f"render_blend: warning: {w}")
    return 0


if __name__ == "__main__":
    code = main()
    if code:
        sys.exit(code)
