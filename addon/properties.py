"""Render settings stored in the scene as ``scene.ercuts``.

:class:`ErcutsRenderSettings` mirrors ``ercuts_core.settings.RenderSettings``
one-to-one: the same property names and defaults (a test checks it), plus a
description on every property. Defaults are read from the core when it can be
imported at registration (the literals here are the fallback for a Blender whose Python
lacks numpy), so a changed core default does not need an add-on change; a new or
renamed setting does, and the mirror test says which. :meth:`ErcutsRenderSettings.to_core` turns it into the
core's frozen dataclass.
"""
from __future__ import annotations

import bpy
from bpy.props import BoolProperty, EnumProperty, FloatProperty, IntProperty, PointerProperty, StringProperty

from . import passes

# Enum numbers are what .blend files store: keep them stable when items are added.
INTEGRATOR_ITEMS = (
    ("ERCUTS", "ERCuts", "Energy-redistribution chains seeded by BDPT, deposited as virtual point "
     "lights and gathered with lightcuts (the paper's method)", 2),
    ("BDPT", "Bidirectional", "Bidirectional path tracing with multiple importance sampling", 0),
    ("PATH", "Path Tracing", "Unidirectional path tracing with next-event estimation (reference)", 1),
)
GATHER_ITEMS = (
    ("LIGHTCUTS", "Lightcuts", "Gather the virtual point lights through the light tree (lightcuts)", 0),
    ("BRUTE_FORCE", "Brute Force", "Gather every virtual point light at every shading point "
     "(slow; shows what the light tree saves)", 1),
    ("STOCHASTIC", "Stochastic Lightcuts", "A cut of at most Stochastic Cut Size nodes, one "
     "virtual point light drawn per node and shading point (Yuksel 2019): unbiased noise that "
     "iterations average away instead of a 2 % bound; cost independent of the light count", 2),
)
SEEDING_ITEMS = (
    ("BDPT", "Bidirectional", "Seed the chains from bidirectional paths (the paper)", 0),
    ("PATH", "Path Tracing", "Seed the chains from unidirectional paths", 1),
)
LIGHTCUT_ERROR_ITEMS = (
    ("NODE", "Per Node", "Refine the cut while some node's error bound exceeds the threshold "
     "(Walter et al. 2005's practice)", 0),
    ("TOTAL", "Total", "Refine the cut while the sum of the nodes' error bounds exceeds the "
     "threshold (the paper's equation 5)", 1),
    ("LITERAL", "Literal", "The paper's per-node text |estimate - exact| < threshold; an "
     "ablation, not a bound", 2),
)
TREE_PAIRING_ITEMS = (
    ("PLOC", "Half per Level", "Pair mutual best matches until half the clusters are paired, "
     "then go up a level", 0),
    ("GREEDY", "Greedy", "Pair mutual best matches until none are left on a level (ablation)", 1),
)
DIRECT_LIGHT_ITEMS = (
    ("NEE", "Light Sampling", "Direct light by anti-aliased next-event estimation from every light; "
     "virtual point lights carry the indirect light only", 0),
    ("VPL", "Virtual Point Lights", "Direct light from area lights and emissive meshes through "
     "virtual point lights on the lights, as in the paper", 1),
)


def _core_defaults() -> dict:
    """``RenderSettings()`` as a dict, or {} when the core cannot be imported here."""
    try:
        from ercuts_core.settings import RenderSettings
    except Exception as exc:  # noqa: BLE001 - e.g. no numpy in this Python: use the fallbacks
        print(f"Ercuts: core settings not importable ({exc}); using built-in defaults")
        return {}
    return RenderSettings().to_dict()


_CORE_DEFAULTS = _core_defaults()


def _default(name: str, fallback):
    """The core's default for ``name`` (so the two cannot drift apart), else ``fallback``."""
    return _CORE_DEFAULTS.get(name, fallback)


def _get_film_transparent(self):
    return bool(self.id_data.render.film_transparent)


def _set_film_transparent(self, value):
    self.id_data.render.film_transparent = bool(value)


def _get_max_error_percent(self):
    return float(self.max_error) * 100.0


def _set_max_error_percent(self, value):
    self.max_error = float(value) / 100.0


def _update_passes(self, context):
    """Refresh the compositor's Render Layers sockets after a pass toggle changed."""
    scene = self.id_data
    for view_layer in getattr(scene, "view_layers", ()):
        view_layer.update_render_passes()


class ErcutsRenderSettings(bpy.types.PropertyGroup):
    """Ercuts core settings (``ercuts_core.RenderSettings``) of one scene."""

    integrator: EnumProperty(
        name="Integrator",
        description="Light transport algorithm",
        items=INTEGRATOR_ITEMS,
        default=_default("integrator", "BDPT"),
    )
    samples: IntProperty(
        name="Samples",
        description="Path Tracing and Bidirectional: samples per pixel (with a time limit, the "
                    "limit is what stops the render, as in Cycles)",
        default=_default("samples", 4096), min=1, soft_max=16384,
    )
    rough_samples: IntProperty(
        name="Rough Samples",
        description="Ercuts: samples per pixel of each iteration's rough bidirectional image, which "
                    "measures the light the chains redistribute (step 1)",
        default=_default("rough_samples", 16), min=1, soft_max=256,
    )
    seed: IntProperty(
        name="Seed",
        description="Random seed; the same seed and settings give the same image",
        default=_default("seed", 0), min=0,
    )
    max_depth: IntProperty(
        name="Max Bounces",
        description="Maximum number of bounces of a light path (1 = direct light only)",
        default=_default("max_depth", 64), min=1, soft_max=64, max=1024,
    )
    rr_depth: IntProperty(
        name="Russian Roulette Depth",
        description="Number of bounces before paths may be terminated at random (Russian roulette)",
        default=_default("rr_depth", 3), min=0, soft_max=64,
    )
    time_limit: FloatProperty(
        name="Time Limit",
        description=("Maximum time in seconds for the whole render, scene export included "
                     "(0 = no limit); the image rendered so far is kept when it runs out"),
        default=_default("time_limit", 0.0), min=0.0, soft_max=3600.0, unit="TIME_ABSOLUTE",
    )
    film_transparent: BoolProperty(
        name="Transparent",
        description=("World background is transparent (alpha = coverage); the same setting as "
                     "Blender's Film > Transparent"),
        default=False,
        get=_get_film_transparent,
        set=_set_film_transparent,
    )
    batch_rays: IntProperty(
        name="Batch Rays",
        description="Rays traced per wavefront batch (more uses more memory but less overhead)",
        default=_default("batch_rays", 1 << 17), min=1024, soft_max=1 << 22,
    )
    threads: IntProperty(
        name="Threads",
        description=("Threads used to trace rays (0 = all cores, or Blender's fixed "
                     "Performance > Threads / -t setting)"),
        default=_default("threads", 0), min=0, soft_max=256,
    )

    max_error: FloatProperty(
        name="Max Error",
        description="Lightcut error threshold, relative to the pixel estimate (0.02 = Weber's law)",
        default=_default("max_error", 0.02), min=0.0, max=1.0, precision=3,
    )
    iterations: IntProperty(
        name="Iterations",
        description=("Complete Ercuts iterations (chains, virtual point lights, light tree and "
                     "gather each time), averaged; 0 = as many as the time limit allows"),
        default=_default("iterations", 0), min=0, soft_max=256,
    )
    iteration_start: IntProperty(
        name="First Iteration",
        description=("Index of the first iteration rendered: renders of the same frame with "
                     "different first iterations can be averaged"),
        default=_default("iteration_start", 0), min=0,
    )
    chains_per_pixel: FloatProperty(
        name="Chains per Pixel",
        description="Average number of energy-redistribution chains started per pixel",
        default=_default("chains_per_pixel", 0.25), min=0.0, soft_max=16.0,
    )
    seed_samples: IntProperty(
        name="Seed Samples",
        description=("Bidirectional seed paths per pixel the energy-redistribution chains start "
                     "from (the paper: 1); more lower the indirect light's coarse noise"),
        default=_default("seed_samples", 4), min=1, soft_max=64,
    )
    max_chains: IntProperty(
        name="Max Chains",
        description=("Energy-redistribution chains per iteration at most: large renders share "
                     "this budget instead of starting chains at every pixel"),
        default=_default("max_chains", 16384), min=1, soft_max=1 << 20,
    )
    chain_length: IntProperty(
        name="Chain Length",
        description="Mutation steps per chain; every step deposits a share of the chain's energy",
        default=_default("chain_length", 100), min=1, soft_max=10000,
    )
    min_chain_length: IntProperty(
        name="Min Chain Length",
        description=("Beyond Max Chains (large renders) the same mutation steps are spread over "
                     "more, shorter chains, down to this length"),
        default=_default("min_chain_length", 20), min=1, soft_max=10000,
    )
    lens_perturbation: BoolProperty(
        name="Lens Perturbation",
        description="Use Veach's lens perturbation (moves the image point of a path)",
        default=_default("lens_perturbation", True),
    )
    caustic_perturbation: BoolProperty(
        name="Caustic Perturbation",
        description="Use Veach's caustic perturbation (moves the light end of a path)",
        default=_default("caustic_perturbation", True),
    )
    multichain_perturbation: BoolProperty(
        name="Multi-chain Perturbation",
        description=("Use Veach's multi-chain perturbation (several specular chains); inactive "
                     "until the core has perfectly specular materials, so not shown"),
        default=_default("multichain_perturbation", True),
    )
    bidirectional_mutation: BoolProperty(
        name="Bidirectional Mutation",
        description="Use bidirectional mutations (replace a sub-path), for large changes",
        default=_default("bidirectional_mutation", True),
    )
    max_cut_size: IntProperty(
        name="Max Cut Size",
        description="Largest lightcut (number of light-tree nodes) evaluated per shading point",
        default=_default("max_cut_size", 1000), min=1, soft_max=100000,
    )
    stochastic_cut_size: IntProperty(
        name="Stochastic Cut Size",
        description=("Light-tree nodes per shading point of the Stochastic Lightcuts gather, "
                     "each evaluated with one virtual point light drawn for the point"),
        default=_default("stochastic_cut_size", 256), min=1, soft_max=1024,
    )
    stochastic_passes: IntProperty(
        name="Stochastic Passes",
        description=("Passes of the Stochastic Lightcuts gather per iteration (new lights drawn in "
                     "each), averaged"),
        default=_default("stochastic_passes", 2), min=1, soft_max=256,
    )
    stochastic_cut_sharing: IntProperty(
        name="Cut Sharing",
        description=("Neighbouring shading points (in a pixel row) that share one Stochastic "
                     "Lightcuts cut, refined once for them (1 = off); points across an edge keep "
                     "their own. Each point still draws its own lights (unbiased)"),
        default=_default("stochastic_cut_sharing", 4), min=1, soft_max=16,
    )
    gather_spacing: IntProperty(
        name="Gather Spacing",
        description=("Gather the virtual point lights at one pixel in k x k and interpolate the "
                     "others where the surface is smooth, diffuse or rough (edges, glossy surfaces "
                     "and what mirrors show are gathered everywhere). 1 = every pixel; "
                     "0 = automatic: 2 from 1280x720"),
        default=_default("gather_spacing", 0), min=0, soft_max=4,
    )
    clamp: FloatProperty(
        name="VPL Clamp",
        description=("Virtual point light clamp: minimum distance as a fraction of the scene's "
                     "bounding diagonal (0 = off); the removed energy is reported"),
        default=_default("clamp", 0.02), min=0.0, soft_max=0.5, precision=3,
    )
    clamp_compensation: BoolProperty(
        name="Clamp Compensation",
        description=("Add back the light the clamp removes near edges and corners with short "
                     "extra rays (bias compensation); off darkens corners"),
        default=_default("clamp_compensation", True),
    )
    gather: EnumProperty(
        name="Gather",
        description="How shading points collect light from the virtual point lights",
        items=GATHER_ITEMS,
        default=_default("gather", "STOCHASTIC"),
    )
    lightcut_error: EnumProperty(
        name="Lightcut Error",
        description="Which error a lightcut bounds by the threshold",
        items=LIGHTCUT_ERROR_ITEMS,
        default=_default("lightcut_error", "TOTAL"),
    )
    tree_pairing: EnumProperty(
        name="Tree Pairing",
        description="How the light tree pairs clusters of virtual point lights",
        items=TREE_PAIRING_ITEMS,
        default=_default("tree_pairing", "PLOC"),
    )
    seeding: EnumProperty(
        name="Seeding",
        description="Which paths start the energy-redistribution chains",
        items=SEEDING_ITEMS,
        default=_default("seeding", "BDPT"),
    )
    direct_light: EnumProperty(
        name="Direct Light",
        description="How light that reaches the camera after one bounce is rendered",
        items=DIRECT_LIGHT_ITEMS,
        default=_default("direct_light", "NEE"),
    )
    direct_samples: IntProperty(
        name="Direct Samples",
        description="Samples per pixel of the direct light (Direct Light: Light Sampling)",
        default=_default("direct_samples", 64), min=1, soft_max=4096,
    )
    shading_samples: IntProperty(
        name="Shading Samples",
        description=("Shading points (camera rays) per pixel for the virtual point light gather: "
                     "each pixel's first point is gathered, the others where they leave its surface "
                     "(edges). 0 = automatic: 4 below 1280x720, 1 from there"),
        default=_default("shading_samples", 0), min=0, soft_max=64,
    )
    e1_samples: IntProperty(
        name="Normalisation Samples",
        description="Shading points per virtual point light used to normalise its intensity",
        default=_default("e1_samples", 256), min=1, soft_max=4096,
    )
    normalize_to_p: BoolProperty(
        name="Normalize to Rough Energy",
        description=("Ablation: scale the virtual point lights' image so its energy equals the "
                     "rough bidirectional pass's (hides the normalisation's bias)"),
        default=_default("normalize_to_p", False),
    )
    memory_budget_mb: IntProperty(
        name="Memory Budget",
        description=("Memory the render may use, in MiB (0 = no limit); batch sizes follow it and "
                     "a render whose estimate exceeds it is refused before allocating"),
        default=_default("memory_budget_mb", 4096), min=0, soft_max=65536,
    )
    cluster: StringProperty(
        name="Cluster",
        description=("Render the iterations of final renders as tasks on a Ray cluster (needs the "
                     "'ray' package in Blender's Python): empty = this computer, 'local' = a Ray "
                     "cluster started here for the render, 'auto' = the running cluster, "
                     "'ray://host:port' or 'host:port'; the image is the same"),
        default=_default("cluster", ""),
    )

    # ---- add-on-only settings (not in RenderSettings; listed in ADDON_ONLY_NAMES)
    max_error_percent: FloatProperty(
        name="Max Error",
        description=("Lightcut error threshold in percent of the pixel estimate (2 % = Weber's "
                     "law); the same setting as Max Error, shown as a percentage"),
        min=0.0, max=100.0, precision=1, subtype="PERCENTAGE",
        get=_get_max_error_percent, set=_set_max_error_percent,
    )
    use_animated_seed: BoolProperty(
        name="Animated Seed",
        description="Add the frame number to the seed, so the noise changes from frame to frame",
        default=False,
    )
    use_denoising: BoolProperty(
        name="Denoising",
        description=("Write the denoiser's guides (Normal, Albedo) and keep the noisy image as "
                     "its own pass; the compositor's Denoise node (OpenImageDenoise) does the "
                     "denoising (see Set Up Denoising)"),
        default=False, update=_update_passes,
    )
    viewport_integrator: EnumProperty(
        name="Viewport Integrator",
        description=("Integrator of the Rendered viewport shading mode; it refines progressively "
                     "(the ERCuts pipeline is not progressive, so the viewport offers the "
                     "unbiased integrators)"),
        items=tuple(item for item in INTEGRATOR_ITEMS if item[0] != "ERCUTS"), default="PATH",
    )
    viewport_samples: IntProperty(
        name="Viewport Samples",
        description="Samples per pixel of the Rendered viewport; each one is shown as it completes",
        default=64, min=1, soft_max=4096,
    )
    write_sidecar: BoolProperty(
        name="Statistics File",
        description=("Write a JSON file with the settings, seed, per-phase timings and VPL/cut "
                     "statistics next to each rendered frame (<output name>.ercuts.json)"),
        default=False,
    )

    def seed_for_frame(self, frame: int) -> int:
        """The core's seed for ``frame``: ``seed``, or ``seed + frame`` with Animated Seed."""
        if not self.use_animated_seed:
            return int(self.seed)
        return (int(self.seed) + int(frame)) % (1 << 31)

    def to_core(self, **overrides):
        """The equivalent ``ercuts_core.settings.RenderSettings`` (``overrides`` win)."""
        from ercuts_core.settings import RenderSettings, quick_time_limit

        values = {name: getattr(self, name) for name in PROPERTY_NAMES}
        for name, value in values.items():
            if isinstance(value, float):  # stored as float32: 0.01 reads back as 0.00999999977
                values[name] = float(f"{value:.7g}")
        render = self.id_data.render
        if values["threads"] == 0 and render.threads_mode == "FIXED":
            values["threads"] = int(render.threads)
        values["time_limit"] = quick_time_limit(values["time_limit"])   # ERCUTS_QUICK (README)
        values.update(overrides)
        return RenderSettings.from_dict(values)

    @classmethod
    def register(cls):
        bpy.types.Scene.ercuts = PointerProperty(
            type=cls, name="Ercuts Settings", description="Ercuts render settings")

    @classmethod
    def unregister(cls):
        del bpy.types.Scene.ercuts


#: Properties of ``scene.ercuts`` that the add-on adds on top of the mirror (not core settings).
ADDON_ONLY_NAMES = ("max_error_percent", "use_animated_seed", "use_denoising", "viewport_integrator",
                    "viewport_samples", "write_sidecar")
#: Names of the mirrored settings, in ``RenderSettings`` order (the class's own order; the
#: mirror test checks it against the core).
PROPERTY_NAMES = tuple(n for n in ErcutsRenderSettings.__annotations__ if n not in ADDON_ONLY_NAMES)


def _pass_toggle(pass_def) -> BoolProperty:
    return BoolProperty(name=pass_def.name, description=pass_def.description, default=False,
                        update=_update_passes)


class ErcutsViewLayerSettings(bpy.types.PropertyGroup):
    """Per-view-layer Ercuts pass toggles (``view_layer.ercuts``; see :mod:`.passes`).

    Depth and Normal use Blender's own ``use_pass_z`` / ``use_pass_normal``.
    """

    __annotations__ = {p.toggle: _pass_toggle(p) for p in passes.OWN_PASSES}

    @classmethod
    def register(cls):
        bpy.types.ViewLayer.ercuts = PointerProperty(
            type=cls, name="Ercuts Passes", description="Ercuts render passes of this view layer")

    @classmethod
    def unregister(cls):
        del bpy.types.ViewLayer.ercuts


classes = (ErcutsRenderSettings, ErcutsViewLayerSettings)


register, unregister = bpy.utils.register_classes_factory(classes)
