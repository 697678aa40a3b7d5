"""Memory estimate of a render, and batch sizes that keep it inside the memory budget.

A wavefront renderer's memory is its arrays: what scales with the scene (triangles), with
the window (films, the ERCUTS G-buffer, chain states, VPLs and the light tree) and with
the batch (ray state of a batch of camera samples, E1 samples, lightcut entries).
:func:`plan` adds them up *before anything is allocated* (shared docs,
style-and-testing.md §2.6: "estimate memory before rendering … choose the batch size from
a memory budget; error with the estimate if even one tile cannot fit"): the batch sizes
are the largest the settings ask for that fit what the window-sized arrays leave of
``RenderSettings.memory_budget_mb``; if even the smallest batches do not fit,
:class:`MemoryBudgetError` names the estimate and its largest parts.

The per-item sizes below come from the array layouts (float64 unless noted) and were
checked with ``tracemalloc`` peaks on the S-corridor (``benchmarks/bench_memory.py``
measures the process's peak RSS). The estimate is of the render's own arrays: the
host process (Python, numpy, embree, Blender) comes on top.
"""
from __future__ import annotations

from dataclasses import dataclass, field

from .settings import RenderSettings
from .validate import SceneError

MIB = 1 << 20

#: Film channels (float64 accumulators): colour 3, splat 3, alpha 1 and the AOVs depth 1,
#: normal 3, albedo 3, emission 3, direct 3, indirect 3.
FILM_CHANNELS = 7 + 16
#: ERCUTS-only AOVs: cut_size 1, chain_deposits 1, vpl_density 1, er_caustic 3.
ERCUTS_AOV_CHANNELS = 6
#: ERCUTS's direct-light passes pooled over the iterations (``direct_light='NEE'``):
#: :attr:`Film.pooled <ercuts_core.film.Film.pooled>`, 3 light passes × RGB.
POOLED_CHANNELS = 9
#: Output per channel: the float32 result.
OUTPUT_BYTES_PER_CHANNEL = 4
#: Bytes per triangle: description (float32 positions, int32 indices, ids), the built
#: scene's float64 copies and normals, and embree's BVH.
TRIANGLE_BYTES = 400
#: The Sobol sequence's tables (:mod:`ercuts_core.qmc`): scipy's initialisation peaks at 6.0 MiB
#: and keeps 1.95 MiB (direction numbers and the first block of points; measured with
#: tracemalloc in a fresh process), once per process — the first render's peak.
SOBOL_BYTES = int(6.5 * MIB)
#: PATH ray state per camera sample of a batch (rays, hits, BSDF, light samples).
PATH_LANE_BYTES = 1600
#: BDPT state per camera sample and path vertex (two subpaths, MIS pdfs, connection rows).
BDPT_LANE_VERTEX_BYTES = 600
#: BDPT connection rows (``max_rows`` = 2^17 rows per round) independent of the batch.
BDPT_FIXED_BYTES = 80 * MIB
#: ERCUTS per shading point: G-buffer (positions, normals, directions, hit record) and the
#: direct-light image with its light-sample temporaries.
GBUFFER_POINT_BYTES = 300
#: … plus, per shading point, the weight and flag of points moved through mirrors and glass
#: (:func:`~ercuts_core.integrators.ercuts.vpl.follow_specular`) and the first-hit AOVs taken
#: before (depth, normal, albedo: float64).
GBUFFER_FOLLOW_BYTES = 3 * 8 + 1 + 7 * 8
#: … plus, per shading point, the gather's interpolation (:mod:`~ercuts_core.integrators.
#: ercuts.interpolation`): four anchors and weights, the reflectance, and the fill's
#: temporaries (the anchors' light parts, their ratio-weighted sum).
GBUFFER_INTERP_BYTES = 4 * 8 + 4 * 4 + 3 * 4 + 4 * 2 * 3 * 8
#: ERCUTS per pixel: the spread of the direct-light and gather passes (two running sums
#: each, :mod:`~ercuts_core.integrators.ercuts.balance`) and a pass's luminance.
BALANCE_PIXEL_BYTES = 5 * 8
#: One path of K vertex slots (position, two normals, material) plus its raster/ids.
PATH_SLOT_BYTES = 3 * 3 * 8 + 8
PATH_FIXED_BYTES = 40
#: Chain state in path sizes: the current paths, plus the copies and proposals of one
#: mutation type's rows (a lock-step round handles one type at a time, about a quarter to
#: a half of the chains) and the contribution temporaries.
CHAIN_PATHS = 2.0
#: Seed paths per pixel of a seed batch (every BDPT connection strategy may seed).
SEEDS_PER_PIXEL = 2.0
#: VPL slots in the chains' store per chain (its initial capacity; it doubles when
#: exceeded) and their bytes (position, normal, home, count, colour).
VPL_SLOTS_PER_CHAIN = 4
VPL_SLOT_BYTES = 96
#: VPLs per chain after merging (measured 0.3–1.3 on the S-corridor), and the bytes of
#: each: the VPL set, the light tree (2 nodes: bounds, cone, intensity, representative)
#: and its builder's temporaries.
VPLS_PER_CHAIN = 1.5
VPL_BYTES = 110 + 2 * 160 + 200
#: Per E1 sample of a chunk: rays, hits, BSDF and camera connection.
E1_SAMPLE_BYTES = 900
#: Per live lightcut entry (point, node, unit radiance, bounds) and refinement temporaries.
CUT_ENTRY_BYTES = 300

#: Smallest batches the renderer will use, and the largest (the defaults before budgets).
MIN_BATCH_PIXELS = 1024
MIN_SEED_PIXELS = 1024
MIN_E1_CHUNK = 1 << 12
MAX_E1_CHUNK = 1 << 18
MIN_GATHER_BATCH = 16
MAX_GATHER_BATCH = 2048


class MemoryBudgetError(SceneError):
    """The render would need more memory than ``memory_budget_mb`` even with the smallest batches."""


@dataclass
class MemoryPlan:
    """Batch sizes for a render and the estimate they give.

    Attributes:
        batch_pixels: camera samples per PATH/BDPT batch (also ERCUTS's rough BDPT image).
        seed_pixels: pixels per batch of ERCUTS seed paths.
        e1_chunk: E1 samples traced together when normalising VPLs.
        gather_batch: shading points per lightcut batch.
        parts: bytes per part of the estimate: the arrays alive for the whole render and
            the largest phase's transient arrays.
        phases: transient bytes of every phase with the chosen batches.
        budget: the budget in bytes (0 = none).
    """

    batch_pixels: int
    seed_pixels: int
    e1_chunk: int
    gather_batch: int
    parts: dict[str, int] = field(default_factory=dict)
    phases: dict[str, int] = field(default_factory=dict)
    budget: int = 0

    @property
    def total(self) -> int:
        """Estimated peak bytes of the render's arrays."""
        return int(sum(self.parts.values()))

    def describe(self) -> str:
        """'1234 MiB (films 500, G-buffer 300, …)': the estimate and its largest parts."""
        top = sorted(self.parts.items(), key=lambda kv: -kv[1])[:4]
        return f"{self.total / MIB:.0f} MiB (" + ", ".join(f"{k} {v / MIB:.0f}" for k, v in top) + ")"


def path_bytes(max_depth: int) -> int:
    """Bytes of one padded eye-first path with ``max_depth + 2`` vertex slots (paths.py)."""
    return (max_depth + 2) * PATH_SLOT_BYTES + PATH_FIXED_BYTES


def lane_bytes(settings: RenderSettings) -> int:
    """Bytes of ray state per camera sample of a PATH or BDPT batch."""
    if settings.integrator == "PATH":
        return PATH_LANE_BYTES
    return BDPT_LANE_VERTEX_BYTES * (settings.max_depth + 1)


def fixed_parts(n_pixels: int, n_triangles: int, settings: RenderSettings) -> dict[str, int]:
    """Bytes alive for the whole render: scene, films and (ERCUTS) window-sized arrays."""
    s = settings
    ercuts = s.integrator == "ERCUTS"
    channels = FILM_CHANNELS + (ERCUTS_AOV_CHANNELS if ercuts else 0) \
        + (POOLED_CHANNELS if ercuts and not s.direct_vpls else 0)
    # Films alive at once: the result and one pass (ERCUTS: the rough BDPT image and its
    # pass; the final film's accumulators are filled at the end, when the pass is gone).
    films = 2
    parts = {
        "scene": n_triangles * TRIANGLE_BYTES,
        "Sobol tables": SOBOL_BYTES,
        "films": n_pixels * channels * (8 * films + OUTPUT_BYTES_PER_CHANNEL),
    }
    if ercuts:
        parts["G-buffer"] = (n_pixels * s.shading_points(n_pixels) * (GBUFFER_POINT_BYTES + GBUFFER_FOLLOW_BYTES
                                                         + GBUFFER_INTERP_BYTES)
                             + n_pixels * BALANCE_PIXEL_BYTES)
        chains = _chains(n_pixels, s)
        parts["VPLs"] = int(chains * (VPL_SLOTS_PER_CHAIN * VPL_SLOT_BYTES + VPLS_PER_CHAIN * VPL_BYTES))
    return parts


def _chains(n_pixels: int, s: RenderSettings) -> int:
    """Expected chains Σ⌊U + e/(N·e_d)⌋ ≈ C·(seed energy / P) (measured 0.95–1.03; C of
    :meth:`~ercuts_core.settings.RenderSettings.chain_plan`), with a margin of 1.25: bounded
    by max_chains · chain_length / min_chain_length at any resolution."""
    return int(1.25 * s.chain_plan(n_pixels)[0])


def phase_parts(n_pixels: int, settings: RenderSettings, batch: int, seeds: int, e1: int,
                gather: int) -> dict[str, int]:
    """Bytes of each phase's transient arrays; phases run one after another, so the peak
    is the largest of them on top of :func:`fixed_parts`."""
    s = settings
    rows = BDPT_FIXED_BYTES if s.integrator != "PATH" else 0
    parts = {"batch": batch * lane_bytes(s) + rows}
    if s.integrator == "ERCUTS":
        parts["seed batch"] = int(seeds * (SEEDS_PER_PIXEL * path_bytes(s.max_depth) + lane_bytes(s))) + rows
        parts["chain states"] = int(_chains(n_pixels, s) * CHAIN_PATHS * path_bytes(s.max_depth))
        parts["E1 chunk"] = e1 * E1_SAMPLE_BYTES
        parts["lightcuts"] = gather * s.max_cut_size * CUT_ENTRY_BYTES
        if not s.direct_vpls:     # the direct-light film and its pass, freed after
            parts["direct light"] = n_pixels * FILM_CHANNELS * 8 * 2
    return parts


def plan(n_pixels: int, n_triangles: int, settings: RenderSettings, shading_bytes: int = 0) -> MemoryPlan:
    """Batch sizes that fit ``settings.memory_budget_mb``; raises :class:`MemoryBudgetError`.

    Args:
        n_pixels: pixels of the rendered window; n_triangles: triangles of the scene.
        shading_bytes: textures and per-corner shading attributes (:func:`shading_bytes`).
    The largest batches are the ones the settings ask for (``batch_rays``; 2^18 E1 samples;
    2048 shading points); all batches shrink by the same factor (down to the minimums)
    until the estimate fits.
    """
    s = settings
    per = s.batch_rays if s.integrator == "PATH" else s.batch_rays // 4
    largest = (max(MIN_BATCH_PIXELS, min(n_pixels, per)), max(MIN_SEED_PIXELS, min(n_pixels, per)),
               MAX_E1_CHUNK, MAX_GATHER_BATCH)
    smallest = (min(MIN_BATCH_PIXELS, largest[0]), min(MIN_SEED_PIXELS, largest[1]), MIN_E1_CHUNK,
                MIN_GATHER_BATCH)
    fixed = fixed_parts(n_pixels, n_triangles, s)
    if shading_bytes:
        fixed["textures"] = int(shading_bytes)
    budget = s.memory_budget_mb * MIB

    def make(scale: float) -> MemoryPlan:
        sizes = [max(lo, int(hi * scale)) for lo, hi in zip(smallest, largest)]
        phases = phase_parts(n_pixels, s, *sizes)
        peak = max(phases, key=phases.get)
        return MemoryPlan(*sizes, parts={**fixed, f"peak phase ({peak})": phases[peak]},
                          phases=phases, budget=budget)

    best = make(1.0)
    if budget <= 0 or best.total <= budget:
        return best
    scale = 1.0
    while scale > 1e-4:
        scale *= 0.5
        candidate = make(scale)
        if candidate.total <= budget:
            return candidate
    least = make(0.0)
    if least.total <= budget:
        return least
    raise MemoryBudgetError(
        f"Render needs about {least.describe()} of memory even with the smallest batches, more "
        f"than the memory budget of {s.memory_budget_mb} MiB: lower the resolution (or render a "
        f"border), reduce chains per pixel or max cut size, or raise the memory budget (0 = no limit)")


#: Bytes per triangle of the built scene's shading tables when UVs / tangents are given
#: (float64 copies of the per-corner attributes, the UV frame and the barycentric duals).
UV_TRIANGLE_BYTES = 3 * 2 * 8 + 3 * 8 + 2 * 8 + 2 * 3 * 8 + 2 * 3 * 8
TANGENT_TRIANGLE_BYTES = 3 * 4 * 8
#: Environment map per texel beyond the description's float32 RGB: the sampling tables of
#: :class:`~ercuts_core.envmap.EnvMap` (float32 cell pdf, one float64 cdf table, temporaries).
ENV_TEXEL_BYTES = 24


def shading_bytes(desc) -> int:
    """Memory of a description's textures (float32, held once), shading attributes and
    environment map (with its sampling tables)."""
    mesh = desc.mesh
    total = desc.textures.nbytes
    if getattr(desc, "world_map", None) is not None:
        rad = desc.world_map.radiance
        total += rad.nbytes + rad.shape[0] * rad.shape[1] * ENV_TEXEL_BYTES
    if mesh.uvs is not None:
        total += mesh.uvs.nbytes + mesh.n_triangles * UV_TRIANGLE_BYTES
    if mesh.tangents is not None:
        total += mesh.tangents.nbytes + mesh.n_triangles * TANGENT_TRIANGLE_BYTES
    return int(total)


def plan_for(desc, settings: RenderSettings) -> MemoryPlan:
    """:func:`plan` for a (validated) :class:`~ercuts_core.description.SceneDescription`."""
    from .camera import render_window
    return plan(render_window(desc.camera).n_pixels, desc.mesh.n_triangles, settings, shading_bytes(desc))
