"""Render a blend_scenes/ file with Cycles (CPU) in this process (the bpy 5.0.1 module).

Settings match the core's estimator so the two converge to the same image: the file's
path length (max_bounces, stored by build_scenes.py) (Cycles max bounces = Ercuts max_depth − 1), no clamping, no light threshold,
caustics on, no denoising, adaptive sampling off, 1-pixel box filter, 2 fixed threads.

Cycles' ``scene.cycles.time_limit`` stops the render after that many seconds of rendering
(synchronisation excluded; checked on 5.0.1), but Cycles reports the *requested* sample count
(EXR header ``cycles.<layer>.samples``, the debug sample-count pass is normalised), not the
count it reached. :func:`render_cycles` therefore asks for a little more than the number of
samples that fits the budget at a rate measured by :func:`calibrate`, with the time limit as
the hard stop, and records both; ``samples`` is exact when ``capped`` is False, an estimate
(rate × render time) otherwise.
"""
from __future__ import annotations

import os
import tempfile
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
BLEND_DIR = os.path.join(ROOT, "blend_scenes")


def _bpy():
    import bpy  # noqa: PLC0415  (only the Cycles rows need Blender)

    return bpy


def open_scene(name: str, width: int, height: int):
    """Open ``blend_scenes/<name>.blend`` and set Cycles up for an unbiased comparison."""
    bpy = _bpy()
    bpy.ops.wm.open_mainfile(filepath=os.path.join(BLEND_DIR, name + ".blend"))
    s = bpy.context.scene
    s.render.engine = "CYCLES"
    s.render.resolution_x, s.render.resolution_y = width, height
    s.render.resolution_percentage = 100
    s.render.threads_mode = "FIXED"
    s.render.threads = os.cpu_count() or 2
    s.render.use_border = False
    c = s.cycles
    c.device = "CPU"
    c.use_denoising = False
    c.use_adaptive_sampling = False
    c.pixel_filter_type = "BOX"
    c.filter_width = 1.0
    c.sample_clamp_direct = c.sample_clamp_indirect = 0.0
    c.light_sampling_threshold = 0.0
    c.caustics_reflective = c.caustics_refractive = True
    c.blur_glossy = 0.0
    c.use_guiding = False
    c.seed, c.use_animated_seed = 0, False
    for key in ("diffuse_bounces", "glossy_bounces", "transmission_bounces", "volume_bounces"):
        setattr(c, key, c.max_bounces)
    c.min_light_bounces = c.min_transparent_bounces = 0
    s.view_settings.view_transform = "Standard"
    ims = s.render.image_settings
    if hasattr(ims, "media_type"):
        ims.media_type = "IMAGE"
    ims.file_format = "OPEN_EXR"
    ims.color_depth = "32"
    s.render.use_file_extension = False
    return s


#: Cycles settings reset to Cycles' own defaults (their RNA defaults) for the "Cycles at its
#: defaults" rows (CYCLES_DEFAULT): what a user gets without touching the render settings
#: (4096 samples with adaptive sampling, OpenImageDenoise, 12 bounces with 4 diffuse,
#: indirect clamp 10, light threshold 0.01, filter glossy 1); the time limit is the budget.
DEFAULT_KEYS = ("samples", "use_adaptive_sampling", "adaptive_threshold", "adaptive_min_samples",
                "use_denoising", "denoiser", "max_bounces", "diffuse_bounces", "glossy_bounces",
                "transmission_bounces", "volume_bounces", "transparent_max_bounces",
                "min_light_bounces", "min_transparent_bounces", "sample_clamp_direct",
                "sample_clamp_indirect", "light_sampling_threshold", "caustics_reflective",
                "caustics_refractive", "blur_glossy", "pixel_filter_type", "filter_width",
                "use_guiding", "use_light_tree")


def open_scene_defaults(name: str, width: int, height: int):
    """:func:`open_scene` with the estimator settings of :data:`DEFAULT_KEYS` back at Cycles'
    own defaults (read from the RNA, so they are this Blender's)."""
    s = open_scene(name, width, height)
    c = s.cycles
    props = c.bl_rna.properties
    for key in DEFAULT_KEYS:
        prop = props.get(key)
        # (an enum whose RNA default is empty, the denoiser in 5.0.1, keeps the file's value)
        if prop is not None and not prop.is_readonly and (prop.type != "ENUM" or prop.default):
            setattr(c, key, prop.default)
    return s


def settings_record(scene) -> dict:
    """The Cycles settings that decide the estimator (stored with every result)."""
    c = scene.cycles
    keys = ("samples", "time_limit", "seed", "max_bounces", "diffuse_bounces", "glossy_bounces",
            "use_adaptive_sampling", "use_denoising", "pixel_filter_type", "filter_width",
            "sample_clamp_direct", "sample_clamp_indirect", "light_sampling_threshold",
            "caustics_reflective", "caustics_refractive", "blur_glossy", "adaptive_threshold",
            "denoiser", "transmission_bounces")
    rec = {k: getattr(c, k) for k in keys}
    rec["threads"] = scene.render.threads
    rec["blender"] = _bpy().app.version_string
    return rec


def _render(scene) -> tuple[np.ndarray, float, dict]:
    """Render the open scene to a temporary EXR: ((h, w, 3) float32 top row first, wall s, header)."""
    import OpenEXR

    from ercuts_core.image_io import read_exr

    fd, path = tempfile.mkstemp(suffix=".exr", prefix="ercuts_cycles_")
    os.close(fd)
    try:
        scene.render.filepath = path
        t0 = time.perf_counter()
        _bpy().ops.render.render(write_still=True)
        wall = time.perf_counter() - t0
        img = read_exr(path)["RGBA"][..., :3]
        with OpenEXR.File(path) as f:
            header = {k: str(v) for k, v in f.header().items() if k.startswith("cycles.")}
    finally:
        os.remove(path)
    return img, wall, header


def _seconds(text: str) -> float:
    """Blender's 'MM:SS.ss' / 'HH:MM:SS.ss' → seconds."""
    out = 0.0
    for part in text.split(":"):
        out = out * 60 + float(part)
    return out


def _header_times(header: dict) -> dict:
    out = {}
    for key, value in header.items():
        for field in ("render_time", "synchronization_time", "total_time"):
            if key.endswith("." + field):
                out[field] = _seconds(value)
    return out


def render_fixed(name: str, samples: int, seed: int, width: int, height: int) -> dict:
    """Cycles at a fixed sample count: {'image', 'wall', 'samples', 'times', 'settings'}."""
    s = open_scene(name, width, height)
    s.cycles.samples, s.cycles.seed, s.cycles.time_limit = int(samples), int(seed), 0.0
    img, wall, header = _render(s)
    return dict(image=img, wall=wall, samples=int(samples), times=_header_times(header),
                settings=settings_record(s), capped=False)


def calibrate(name: str, width: int, height: int, samples: int = 16) -> float:
    """Cycles samples per second of *render* time on this scene (one short fixed render)."""
    r = render_fixed(name, samples, 12345, width, height)
    t = r["times"].get("render_time", r["wall"])
    return samples / max(t, 1e-3)


def render_cycles_defaults(name: str, budget: float, seed: int, width: int, height: int) -> dict:
    """Cycles at its own defaults (:func:`open_scene_defaults`) with ``time_limit`` = the budget
    (minus the sync allowance): what a user who sets only a time limit gets. 'samples' is
    Cycles' requested count (adaptive sampling and the limit stop it earlier)."""
    s = open_scene_defaults(name, width, height)
    s.cycles.seed, s.cycles.time_limit = int(seed), max(budget - 0.1, 0.05)
    img, wall, header = _render(s)
    return dict(image=img, wall=wall, samples=int(s.cycles.samples), times=_header_times(header),
                settings=settings_record(s), capped=True)


def render_cycles(name: str, budget: float, seed: int, width: int, height: int, rate: float) -> dict:
    """Cycles for ``budget`` seconds of wall time: samples = 1.15 × rate × (budget − sync), so
    that ``time_limit`` normally stops it and Cycles gets the whole budget even when the machine
    is faster than at calibration. Returns :func:`render_fixed`'s record plus 'capped' (the
    limit stopped it, so 'samples' is the estimate rate × render time)."""
    s = open_scene(name, width, height)
    sync = 0.1  # measured scene sync + film write for these scenes: 0.01–0.06 s
    limit = max(budget - sync, 0.05)
    requested = max(1, int(1.15 * rate * limit))
    s.cycles.samples, s.cycles.seed, s.cycles.time_limit = requested, int(seed), limit
    img, wall, header = _render(s)
    times = _header_times(header)
    rt = times.get("render_time", wall)
    capped = rt >= limit - 0.02
    reached = min(requested, int(round(rate * rt))) if capped else requested
    return dict(image=img, wall=wall, samples=reached, samples_requested=requested, times=times,
                settings=settings_record(s), capped=bool(capped))
