"""Render a frame range of a .blend on a Ray cluster: one EXR per frame, Blender's file names.

    .venv/bin/python blend_scenes/render_frames.py blend_scenes/cornell_box.blend -s 1 -e 4 \\
        --cluster local -o out/frames/cornell_box_####
    PYTHONPATH=.venv/lib/python3.11/site-packages:. blender -b --factory-startup --python-exit-code 1 \\
        --python blend_scenes/render_frames.py -- blend_scenes/cornell_box.blend --cluster auto

Each frame is exported once, here, with the add-on's exporter (the scene description goes into
Ray's object store as ``.npz`` bytes); the workers run only ``ercuts_core`` (numpy + embreex, no
Blender) and render the frame's iterations (:mod:`ercuts_core.cluster`), while this process
exports the next frames. Every frame is written when its last iteration is merged, atomically,
as a scene-linear 32-bit float RGBA EXR of the rendered window, at the path Blender would give
it (``render.frame_path``: a run of ``#`` becomes the zero-padded frame number, without one four
digits are appended, and ``.exr``). The frame range and output default to the file's own.
Options override ``scene.ercuts`` (``--iterations``, ``--samples``, ``--seed``, ``--time-limit``).
With ``--checkpoint`` each frame keeps ``<output>.ckpt.npz`` while it renders: after an
interruption (Ctrl-C, a lost driver) the same command resumes the frame from its merged
iterations (the checkpoint goes once the frame's EXR is written). The exit status is non-zero,
and the frame's file is not written, when a frame fails or the render is interrupted.
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

if HERE not in sys.path:
    sys.path.insert(0, HERE)

import addon  # noqa: E402  (before bpy-dependent imports of the core; see addon.compat)
import bpy  # noqa: E402
from render_blend import open_blend  # noqa: E402

#: Seconds between two progress lines.
PROGRESS_SECONDS = 5.0


def parse(argv):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("blend", help=".blend file to render")
    p.add_argument("-o", "--output", help="output path, '#' for the frame number "
                                          "(default: the file's Output path)")
    p.add_argument("-s", "--start", type=int, help="first frame (default: the file's)")
    p.add_argument("-e", "--end", type=int, help="last frame (default: the file's)")
    p.add_argument("-j", "--step", type=int, help="frame step (default: the file's)")
    p.add_argument("--cluster", default="local",
                   help="'local' (a Ray cluster on this machine for the run), 'auto', ray://HOST:PORT "
                        "or HOST:PORT; default: %(default)s")
    p.add_argument("--iterations", type=int)
    p.add_argument("--samples", type=int)
    p.add_argument("--seed", type=int)
    p.add_argument("--time-limit", type=float, help="seconds per frame")
    p.add_argument("--resolution", type=int, nargs=2, metavar=("W", "H"))
    p.add_argument("--checkpoint", action="store_true",
                   help="keep <output>.ckpt.npz per frame while it renders and resume from it")
    p.add_argument("--skip-existing", action="store_true",
                   help="skip frames whose file exists (Blender's Overwrite off)")
    return p.parse_args(argv)


def open_scene(args):
    """Load the .blend and apply the command line's overrides; returns its scene."""
    scene = open_blend(args.blend, args.resolution)
    for key in ("iterations", "samples", "seed", "time_limit"):
        value = getattr(args, key)
        if value is not None:
            setattr(scene.ercuts, key, value)
    if args.output:
        scene.render.filepath = os.path.abspath(args.output)
    addon.compat.set_single_layer_exr(scene.render.image_settings)
    scene.render.use_file_extension = True
    return scene


def frame_numbers(scene, args) -> list[int]:
    start = scene.frame_start if args.start is None else args.start
    end = scene.frame_end if args.end is None else args.end
    step = scene.frame_step if args.step is None else args.step
    return list(range(start, end + 1, max(step, 1)))


def export_frames(scene, frames, args, name: str):
    """Yield each frame's :class:`~ercuts_core.cluster.FrameJob` (exported when the cluster has
    room for it), skipping existing files with ``--skip-existing``."""
    from addon.export import export_scene
    from ercuts_core.cluster import frame_job

    for f in frames:
        path = scene.render.frame_path(frame=f)
        if args.skip_existing and os.path.exists(path):
            print(f"render_frames: frame {f}: {path} exists, skipped", flush=True)
            continue
        scene.frame_set(f)
        exported = export_scene(bpy.context.evaluated_depsgraph_get())
        for w in exported.warnings:
            print(f"render_frames: frame {f}: warning: {w}", flush=True)
        settings = scene.ercuts.to_core(seed=scene.ercuts.seed_for_frame(f), cluster=args.cluster)
        yield frame_job(exported.description, settings, scene=name, frame=f,
                        checkpoint=path + ".ckpt.npz" if args.checkpoint else None)


def save_exr(scene, path: str, rgba) -> None:
    """Write (h, w, 4) float32 linear RGBA (top row first) to ``path`` with Blender's own EXR
    writer (32-bit float, the core's OpenEXR module clashes with Blender 3.x's library),
    atomically: a temporary file beside ``path``, renamed over it once complete."""
    import numpy as np

    from ercuts_core.atomic import atomic_path

    h, w = rgba.shape[:2]
    image = bpy.data.images.new("ercuts_frame", w, h, alpha=True, float_buffer=True)
    try:
        image.pixels.foreach_set(np.ascontiguousarray(rgba[::-1], np.float32).reshape(-1))
        ims = scene.render.image_settings
        ims.color_depth, ims.color_mode = "32", "RGBA"
        with atomic_path(path, ".exr") as tmp:
            image.save_render(tmp, scene=scene)
    finally:
        bpy.data.images.remove(image)


def main(argv=None) -> int:
    if argv is None:
        argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else sys.argv[1:]
    args = parse(argv)
    from ercuts_core.cluster import ClusterError, render_frames
    from ercuts_core.settings import valid_cluster_address
    from ercuts_core.validate import SceneError

    if not valid_cluster_address(args.cluster) or not args.cluster:
        print(f"render_frames: --cluster {args.cluster!r} is not 'local', 'auto', ray://HOST:PORT "
              "or HOST:PORT", file=sys.stderr)
        return 2
    scene = open_scene(args)
    frames = frame_numbers(scene, args)
    name = os.path.splitext(os.path.basename(args.blend))[0]
    t0 = time.monotonic()
    last = [-float("inf")]

    def progress(fraction, message):
        if time.monotonic() - last[0] >= PROGRESS_SECONDS:
            print(f"render_frames: {100 * fraction:.0f}% {message}", flush=True)
            last[0] = time.monotonic()

    def write(job, result):
        path = scene.render.frame_path(frame=job.frame)
        save_exr(scene, path, result.image)
        if job.checkpoint and os.path.exists(job.checkpoint):
            os.unlink(job.checkpoint)
        print(f"render_frames: frame {job.frame}: {result.summary()} -> {path}", flush=True)

    try:
        render_frames(export_frames(scene, frames, args, name), args.cluster, write, progress,
                      frames_total=len(frames))
    except (ClusterError, SceneError, addon.export.ExportError) as exc:
        print(f"render_frames: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("render_frames: interrupted; frames not finished are not written"
              + (" (their checkpoints are kept)" if args.checkpoint else ""), file=sys.stderr)
        return 1
    print(f"render_frames: {len(frames)} frames of {args.blend} in {time.monotonic() - t0:.1f} s", flush=True)
    return 0


if __name__ == "__main__":
    code = main()
    if code:
        sys.exit(code)
