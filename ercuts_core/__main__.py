"""Render a scene description (.npz) or a built-in scene to EXR + PNG, with a progress bar.

examples:
  python -m ercuts_core render builtin:s_corridor -o out/s_corridor.exr --samples 64
  python -m ercuts_core render bug_report.npz -o out/frame.exr --integrator PATH
  python -m ercuts_core save-builtin cornell_box cornell.npz
  python -m ercuts_core render builtin:cornell_box -o out/c.exr --iterations 4 --cluster local
"""
# The module docstring is the --help text: plain text, no reStructuredText markup.
from __future__ import annotations

import argparse
import json
import os
import sys
import time

from . import __version__
from .description import load_npz, save_npz
from .image_io import write_exr, write_png
from .render import render
from .scenes import SCENES
from .settings import RenderSettings, quick_time_limit, valid_cluster_address
from .validate import SceneError


def _load(spec: str, width: int | None, height: int | None):
    if spec.startswith("builtin:"):
        name = spec.split(":", 1)[1]
        if name not in SCENES:
            raise SystemExit(f"unknown built-in scene {name!r}; choose from {sorted(SCENES)}")
        kwargs = {}
        if width:
            kwargs["width"] = width
        if height:
            kwargs["height"] = height
        return SCENES[name](**kwargs)
    return load_npz(spec)


#: Seconds between two progress-bar redraws on a terminal, and in a log (stderr not a
#: terminal: every redraw is a new chunk of the log, so far fewer).
BAR_INTERVAL_TTY, BAR_INTERVAL_LOG = 1.0, 5.0


def _progress_bar():
    """A tqdm progress callback (fraction, message) -> None that redraws at most every
    :data:`BAR_INTERVAL_TTY` s on a terminal and :data:`BAR_INTERVAL_LOG` s in a log."""
    from tqdm import tqdm

    interval = BAR_INTERVAL_TTY if sys.stderr.isatty() else BAR_INTERVAL_LOG
    bar = tqdm(total=1000, unit="‰", file=sys.stderr, dynamic_ncols=True, leave=True,
               mininterval=interval, maxinterval=max(interval, 10.0))

    def progress(fraction: float, message: str):
        bar.set_description(message, refresh=False)
        bar.update(max(int(fraction * 1000) - bar.n, 0))     # redraws only after `interval`
        return None

    return bar, progress


def _cluster_address(value: str) -> str:
    """argparse type of ``--cluster``: an address :attr:`RenderSettings.cluster` accepts."""
    if not value or not valid_cluster_address(value):
        raise argparse.ArgumentTypeError(f"{value!r} is not 'local', 'auto', ray://HOST:PORT or HOST:PORT")
    return value


def cmd_render(args) -> int:
    desc = _load(args.scene, args.width, args.height)
    settings = RenderSettings(integrator=args.integrator, samples=args.samples,
                              rough_samples=args.rough_samples, seed=args.seed,
                              max_depth=args.max_depth, time_limit=quick_time_limit(args.time_limit),
                              iterations=args.iterations, cluster=args.cluster or "")
    if args.checkpoint and not args.cluster:
        print("error: --checkpoint needs --cluster (use --cluster local on one machine)", file=sys.stderr)
        return 2
    bar, progress = _progress_bar()
    t0 = time.perf_counter()
    try:
        result = _render(desc, settings, progress, args)
    except SceneError as exc:
        bar.close()
        print(f"error: {exc}", file=sys.stderr)
        return 2
    bar.close()
    for issue in result.issues:
        print(f"{issue.severity}: {issue.message}", file=sys.stderr)
    write_exr(args.output, result.image)
    if args.checkpoint and result.stopped_by is None and os.path.exists(args.checkpoint):
        os.unlink(args.checkpoint)          # the frame is complete: nothing left to resume
    png = args.png or os.path.splitext(args.output)[0] + ".png"
    write_png(png, result.image)
    print(f"Ercuts {__version__} {settings.integrator}: {result.summary()}")
    print("timings: " + ", ".join(f"{k} {v:.2f} s" for k, v in result.timings.items()))
    print(f"wrote {args.output} and {png} in {time.perf_counter() - t0:.2f} s")
    if args.stats:
        with open(args.stats, "w") as fh:
            json.dump({"settings": settings.to_dict(), "timings": result.timings,
                       "stats": result.stats}, fh, indent=2)
    return 0


def _render(desc, settings: RenderSettings, progress, args):
    """``render`` here, or with ``--cluster`` on the cluster (:mod:`ercuts_core.cluster`): a task
    error or a missing ``ray`` becomes a :class:`SceneError`-like one-line error."""
    if not args.cluster:
        return render(desc, settings, progress)
    from .cluster import ClusterError, render as cluster_render

    try:
        return cluster_render(desc, settings, progress, scene=args.scene, checkpoint=args.checkpoint)
    except ClusterError as exc:
        raise SceneError(str(exc)) from exc


def cmd_save_builtin(args) -> int:
    save_npz(SCENES[args.name](), args.output)
    print(f"wrote {args.output}")
    return 0


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m ercuts_core", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = parser.add_subparsers(dest="command", required=True)
    r = sub.add_parser("render", help="render a scene to EXR (+ PNG preview)",
                       description="Render a scene to a linear EXR and an sRGB PNG preview; "
                                   "print the timings and statistics.")
    r.add_argument("scene", help=f"path to a .npz description, or builtin:NAME "
                                 f"(NAME: {', '.join(sorted(SCENES))})")
    r.add_argument("-o", "--output", required=True, help="output .exr path")
    r.add_argument("--png", help="PNG preview path (default: beside the EXR)")
    defaults = RenderSettings()
    r.add_argument("--integrator", default=defaults.integrator, choices=("ERCUTS", "BDPT", "PATH"),
                   help="default: %(default)s")
    r.add_argument("--samples", type=int, default=defaults.samples,
                   help="PATH/BDPT samples per pixel (with --time-limit the limit stops the render, "
                        "as in Cycles); default: %(default)s")
    r.add_argument("--rough-samples", type=int, default=defaults.rough_samples,
                   help="ERCUTS: samples per pixel of each iteration's rough BDPT image; "
                        "default: %(default)s")
    r.add_argument("--seed", type=int, default=defaults.seed, help="default: %(default)s")
    r.add_argument("--max-depth", type=int, default=defaults.max_depth,
                   help="scattering vertices per path; default: %(default)s")
    r.add_argument("--iterations", type=int, default=defaults.iterations,
                   help="ERCUTS iterations averaged (0 = as many as --time-limit allows)")
    r.add_argument("--time-limit", type=float, default=0.0, help="seconds, 0 = none")
    r.add_argument("--width", type=int, help="built-in scenes only: image width in pixels")
    r.add_argument("--height", type=int, help="built-in scenes only: image height in pixels")
    r.add_argument("--stats", help="write settings, timings and statistics as JSON here")
    r.add_argument("--cluster", metavar="ADDRESS", type=_cluster_address,
                   help="render the iterations as tasks on a Ray cluster (needs the 'cluster' extra): "
                        "'local' starts one on this machine for the call, 'auto' joins the running "
                        "one, or ray://HOST:PORT, HOST:PORT; the same image as without it")
    r.add_argument("--checkpoint", metavar="PATH",
                   help="with --cluster: keep the merged iterations in this .npz while rendering and "
                        "resume from it when it exists (same scene and settings); removed once the "
                        "image is written")
    r.set_defaults(func=cmd_render)
    s = sub.add_parser("save-builtin", help="save a built-in scene as .npz",
                       description="Save a built-in scene as one .npz scene description.")
    s.add_argument("name", choices=sorted(SCENES))
    s.add_argument("output")
    s.set_defaults(func=cmd_save_builtin)
    args = parser.parse_args(argv)
    return args.func(args)


if __name__ == "__main__":
    sys.exit(main())
