"""JSON statistics file written next to a rendered frame (``scene.ercuts.write_sidecar``).

For the frame whose image goes to ``out/shot_0007.exr`` (:func:`image_path`: Blender's
naming for animations and for stills) the sidecar is ``out/shot_0007.ercuts.json``:

    {"format": "ercuts-sidecar", "version": 1, "frame": 7, "image": "<frame path>",
     "blender": "5.0.1", "layers": {"<view layer>": <layer report>, ...}}

A layer report is the core's ``RenderResult.report_dict(settings)`` (settings, seed,
per-phase timings, VPL and cut statistics, issues, cancelled, window) plus the
add-on's export time, total time and warnings. Every view layer of the frame adds its
report, and the file is rewritten atomically (temporary file + ``os.replace``) each
time, so a reader never sees a half-written file; it gets the permissions a plain ``open``
would give (``0o666 & ~umask``), like the image.
"""
from __future__ import annotations

import json
import math
import os

import bpy

#: Extensions stripped from the frame path before adding ``.ercuts.json``.
IMAGE_EXTENSIONS = {".exr", ".png", ".jpg", ".jpeg", ".tif", ".tiff", ".hdr", ".bmp", ".tga",
                    ".webp", ".jp2", ".j2c", ".dpx", ".cin", ".rgb", ".sgi"}
SUFFIX = ".ercuts.json"

#: Reports of the frame being rendered, by sidecar path (one engine instance per frame,
#: so the layers of a frame are collected here).
_pending: dict[str, dict] = {}


def image_path(scene, frame: int, animation: bool) -> str:
    """Where Blender writes the frame's image (verified on 3.4.1 and 5.0.1).

    Animations and command-line frames (``-f``/``-a``, ``is_animation``):
    ``render.frame_path(frame=…)`` ('#' → frame digits, digits appended when there is no
    '#'). Stills (``render.render(write_still=True)``): ``render.filepath`` as it is
    (no frame substitution) plus the format's extension when ``use_file_extension``.
    """
    render = scene.render
    if animation:
        return bpy.path.abspath(render.frame_path(frame=frame))
    path = bpy.path.abspath(render.filepath)
    ext = render.file_extension
    if render.use_file_extension and ext and not path.lower().endswith(ext.lower()):
        path += ext
    return path


def sidecar_path(image: str) -> str:
    """The sidecar of ``image``: its image extension replaced by ``.ercuts.json``."""
    stem, ext = os.path.splitext(image)
    if ext.lower() not in IMAGE_EXTENSIONS:
        stem = image
    return stem + SUFFIX


def layer_report(result, settings, extra: dict) -> dict:
    """The report of one view layer: the core's ``report_dict`` (or its parts) + ``extra``."""
    if hasattr(result, "report_dict"):
        report = dict(result.report_dict(settings))
    else:  # core without report_dict: the same information from the result's fields
        report = {"settings": settings.to_dict(), "seed": settings.seed,
                  "timings": dict(result.timings), "stats": dict(result.stats),
                  "issues": [i.message for i in result.issues],
                  "cancelled": bool(result.cancelled), "window": list(result.window)}
    report.update(extra)
    return report


def _plain(value):
    """JSON fallback for values json cannot encode (sets, objects): sorted list or str."""
    if isinstance(value, (set, frozenset)):
        return sorted(value)
    return str(value)


def _finite(value):
    """``value`` with NaN/inf floats replaced by None (strict JSON has neither)."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {str(k): _finite(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_finite(v) for v in value]
    if hasattr(value, "tolist"):  # numpy scalar or array
        return _finite(value.tolist())
    return value


def write_atomic(path: str, data: dict) -> None:
    """Write ``data`` as strict JSON to ``path`` atomically, readable like the frame beside
    it (the core's :mod:`ercuts_core.atomic`; directories are created)."""
    from . import compat

    compat.preload_embreex()        # before the core's first import (see compat)
    from ercuts_core.atomic import atomic_open

    data = _finite(data)
    with atomic_open(path, "w", encoding="utf-8") as f:
        json.dump(data, f, indent=1, default=_plain, allow_nan=False)


def add_layer(scene, frame: int, animation: bool, layer_name: str, report: dict,
              first_layer: bool) -> str:
    """Add ``report`` for ``layer_name`` to the frame's sidecar and rewrite it; its path."""
    image = image_path(scene, frame, animation)
    path = sidecar_path(image)
    if first_layer or path not in _pending:
        _pending[path] = {"format": "ercuts-sidecar", "version": 1, "frame": int(frame),
                          "image": image, "blender": ".".join(str(v) for v in bpy.app.version),
                          "layers": {}}
    _pending[path]["layers"][layer_name] = report
    write_atomic(path, _pending[path])
    return path
