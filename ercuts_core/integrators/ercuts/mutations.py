"""Veach's path mutations for the ER chains, vectorized over a batch of chains.

Each mutation proposes y from x and returns ``ratio = T(x|y) / T(y|x)`` so that the
acceptance of the paper's eq. (1) is ``a = min(1, f(y)·ratio / f(x))`` [Veach & Guibas 1997].
All of them work in the measure of :mod:`.paths` (raster position of x1, then
area/counting/solid-angle measures for x2 … x_k).

* **Lens perturbation** [Veach 1997 §11.4.3; Mitsuba ``mut_lens.cpp``]: move the raster
  position by r ∈ [0.1 px, √(0.05·W·H/π) px] with density ∝ 1/r, re-trace x1 (from the
  path's own lens point x0 with depth of field), reconnect to the fixed x2. Symmetric: ratio = 1.
* **Caustic perturbation** [Veach 1997 §11.4.4; Mitsuba ``mut_caustic.cpp``]: rotate the
  direction x2 → x1 by θ ∈ [θ1, θ2] (∝ 1/θ, scaled by |x0x1|/|x1x2| so x1 moves about as
  much as under the lens perturbation), re-trace x1 from the fixed x2 and connect it to
  the pinhole (the path's lens point x0). The angular density is symmetric and cancels; the
  Jacobian from raster to the direction at x2 does not: ratio = J(x)/J(y),
  J = cos³θ_cam·|x0x1|²/|x1x2|² (the same with a thin lens, θ measured at x0).
* **Multi-chain perturbation** [Veach 1997 §11.4.5]: needs two specular chains; the
  material model has no delta lobes, so it never applies (reported as 0 proposals).
* **Bidirectional mutation** [Veach 1997 §11.4.2], restricted to deletions that start at
  x1 so that x2 always moves (shared docs, algorithm.md §G.2): delete x2 … x_{m−1}
  (m uniform in {3 … k+1}; m = k+1 also replaces the light vertex), pick the new
  length with Mitsuba's two-tailed geometric law (base 2, centred on the deleted length),
  regenerate the gap by BSDF sampling from x1 and connect it to x_m (or sample a new light
  vertex). ratio = [p_sel(y→x)·P(k_d|k_a)·p(old vertices)] / [p_sel(x→y)·P(k_a|k_d)·p(new)].
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ...arrays import take_rows
from ...lights import AREA, ENV, SUN, TRI
from ...sampling import coordinate_system
from ...scene import BuiltScene
from ...vecmath import dot, normalize
from .paths import PathBatch, edge_visible, slot_rows, x1_clear

LENS, CAUSTIC, MULTICHAIN, BIDIR = 0, 1, 2, 3
NAMES = ("lens", "caustic", "multichain", "bidirectional")
#: Mutations that cannot apply yet: the multi-chain perturbation needs two specular chains,
#: and the materials have no delta lobes (:func:`applicable`). Not reported in the stats.
INACTIVE = ("multichain",)



@dataclass
class Proposal:
    """Proposed paths for a subset of chains.

    Attributes:
        paths: the proposals y (same length as the subset).
        ratio: (n,) T(x|y)/T(y|x).
        valid: (n,) False where the proposal failed (treated as a rejection, a = 0).
        x2_changed: (n,) True where y has a new x2 (a new VPL).
    """

    paths: PathBatch
    ratio: NDArray
    valid: NDArray
    x2_changed: NDArray


class MutationContext:
    """Per-render constants of the mutations (camera window, jump sizes, depth limit, target class)."""

    def __init__(self, scene: BuiltScene, max_edges: int, direct: bool = True, clear_x1: bool = True):
        self.scene = scene
        self.max_edges = max_edges
        self.direct = direct            # target class includes x2 on a light (is_target)
        #: x1 and x2 may lie on mirrors or glass (False when the gather follows the camera
        #: through them: a mutation that moves x1 or x2 there is a failed proposal,
        #: :func:`.paths.x1_or_x2_clear`)
        self.clear_x1 = clear_x1
        cam = scene.camera
        w = cam.window
        self.r1 = 0.1
        self.r2 = max(np.sqrt(0.05 * w.width * w.height / np.pi), 2 * self.r1)
        # Angle subtended by one pixel at the image centre (radians).
        self.rad_per_pixel = min((cam.xmax - cam.xmin) / cam.width, (cam.ymax - cam.ymin) / cam.height)

    def sample_radius(self, u: NDArray, lo: NDArray | float, hi: NDArray | float) -> NDArray:
        """r ∈ [lo, hi] with density ∝ 1/r (exponential sampling)."""
        return hi * np.exp(-np.log(hi / lo) * u)


# ----------------------------------------------------------------------------- helpers
def _set_vertex(paths: PathBatch, rows: NDArray, slot: NDArray | int, p, ng, ns, mat) -> None:
    paths.p[rows, slot] = p
    paths.ng[rows, slot] = ng
    paths.ns[rows, slot] = ns
    paths.mat[rows, slot] = mat


def _x1_allowed(ctx: MutationContext, y: PathBatch, rows: NDArray, vertex: int = 1) -> NDArray:
    """(len(rows),) the proposals' new x1 (or x_``vertex``) may be the chains'
    (:attr:`MutationContext.clear_x1`)."""
    if ctx.clear_x1 or len(rows) == 0:
        return np.ones(len(rows), bool)
    return ~x1_clear(ctx.scene, y.take(rows), vertex)


def _in_window(scene: BuiltScene, raster: NDArray) -> NDArray:
    w = scene.camera.window
    return ((raster[:, 0] >= w.x0) & (raster[:, 0] < w.x0 + w.width) &
            (raster[:, 1] >= w.y0) & (raster[:, 1] < w.y0 + w.height))


# ----------------------------------------------------------------------------- lens
def lens_perturbation(ctx: MutationContext, x: PathBatch, rng: np.random.Generator) -> Proposal:
    """Perturb the raster position of x1 and reconnect to the fixed x2 (ratio 1)."""
    scene = ctx.scene
    n = len(x)
    y = x.copy()
    r = ctx.sample_radius(rng.random(n), ctx.r1, ctx.r2)
    phi = 2 * np.pi * rng.random(n)
    y.raster = x.raster + np.c_[r * np.cos(phi), r * np.sin(phi)]
    valid = _in_window(scene, y.raster)
    o, d = scene.camera.rays_from(y.raster, x.p[:, 0])      # the path's lens point stays
    surf = scene.intersect(o, d)
    valid &= surf.valid
    rows = np.flatnonzero(valid)
    _set_vertex(y, rows, 1, surf.p[rows], surf.ng[rows], surf.ns[rows], surf.mat[rows])
    valid[rows[~_x1_allowed(ctx, y, rows)]] = False
    rows = np.flatnonzero(valid)
    if len(rows):
        vis = edge_visible(scene, y.take(rows), np.ones(len(rows), np.int64))
        valid[rows[~vis]] = False
    return Proposal(y, np.ones(n), valid, np.zeros(n, bool))


# ----------------------------------------------------------------------------- caustic
def _jacobian(scene: BuiltScene, paths: PathBatch) -> NDArray:
    """|dω/du| up to the constant A_pix: the raster → direction-at-x2 Jacobian.

    dω_cam = A_pix·cos³θ du, dA(x1) = |x0x1|²·dω_cam/|cos₀₁|, dω = |cos₁₂|·dA(x1)/|x1x2|², so
    J = cos³θ·|x0x1|²·|cos₁₂| / (|x1x2|²·|cos₀₁|) with the cosines taken at x1's normal.
    """
    w01, l01 = normalize(paths.p[:, 0] - paths.p[:, 1])
    w12, l12 = normalize(paths.p[:, 2] - paths.p[:, 1])
    n1 = paths.ng[:, 1]
    cos = np.maximum(-(w01 @ scene.camera.forward), 1e-12)
    cos01 = np.maximum(np.abs(dot(n1, w01)), 1e-12)
    cos12 = np.abs(dot(n1, w12))
    return cos**3 * l01 * l01 * cos12 / (np.maximum(l12 * l12, 1e-300) * cos01)


def caustic_perturbation(ctx: MutationContext, x: PathBatch, rng: np.random.Generator) -> Proposal:
    """Rotate the direction x2 → x1, re-trace x1 and connect it to the pinhole."""
    scene = ctx.scene
    cam = scene.camera
    n = len(x)
    y = x.copy()
    valid = np.full(n, not cam.ortho)
    w, d12 = normalize(x.p[:, 1] - x.p[:, 2])
    d01 = np.linalg.norm(x.p[:, 1] - x.p[:, 0], axis=1)
    factor = d01 / np.maximum(d12, 1e-300)
    th1 = ctx.rad_per_pixel * ctx.r1 * factor
    th2 = ctx.rad_per_pixel * ctx.r2 * factor
    theta = ctx.sample_radius(rng.random(n), th1, th2)
    valid &= theta < np.pi / 2
    phi = 2 * np.pi * rng.random(n)
    t, b = coordinate_system(w)
    w2 = (np.cos(theta)[:, None] * w + np.sin(theta)[:, None] *
          (np.cos(phi)[:, None] * t + np.sin(phi)[:, None] * b))
    o = scene.tracer.offset(x.p[:, 2], x.ng[:, 2], w2)
    surf = scene.intersect(o, w2)
    valid &= surf.valid
    rows = np.flatnonzero(valid)
    _set_vertex(y, rows, 1, surf.p[rows], surf.ng[rows], surf.ns[rows], surf.mat[rows])
    valid[rows[~_x1_allowed(ctx, y, rows)]] = False
    raster, on_film = cam.raster_of(surf.p, x.p[:, 0] if cam.has_lens else None)
    valid &= on_film
    y.raster = np.where(valid[:, None], raster, x.raster)
    rows = np.flatnonzero(valid)
    if len(rows):
        seen = scene.tracer.visible(np.ascontiguousarray(x.p[rows, 0]), None,
                                    surf.p[rows], surf.ng[rows])
        valid[rows[~seen]] = False
    # The reverse move must be able to rotate back: θ inside y's own (scaled) range. The
    # 1/θ densities then have equal normalisation (ln(θ2/θ1) is scale-free) and cancel.
    d01y = np.linalg.norm(y.p[:, 1] - y.p[:, 0], axis=1)
    d12y = np.linalg.norm(y.p[:, 1] - y.p[:, 2], axis=1)
    fy = d01y / np.maximum(d12y, 1e-300)
    valid &= (theta >= ctx.rad_per_pixel * ctx.r1 * fy) & (theta <= ctx.rad_per_pixel * ctx.r2 * fy)
    ratio = np.where(valid, _jacobian(scene, x) / np.maximum(_jacobian(scene, y), 1e-300), 0.0)
    return Proposal(y, ratio, valid, np.zeros(n, bool))


# ----------------------------------------------------------------------------- bidirectional
def two_tailed_geometric(center: NDArray, lo: NDArray, hi: NDArray, size: int) -> NDArray:
    """(n, size) pmf table P(i) ∝ 2^{−|i − center|} on [lo, hi] (Mitsuba ``TwoTailedGeoDistr``)."""
    i = np.arange(size)[None, :]
    w = np.where((i >= lo[:, None]) & (i <= hi[:, None]), 2.0 ** (-np.abs(i - center[:, None])), 0.0)
    s = w.sum(axis=1, keepdims=True)
    return w / np.where(s > 0, s, 1.0)


def _walk_pdf(scene: BuiltScene, paths: PathBatch, rows: NDArray, j: NDArray) -> NDArray:
    """Area density of generating vertex j from j−1 by BSDF sampling (wo toward j−2)."""
    prev2, prev, cur = (slot_rows(paths.p, rows, j - k) for k in (2, 1, 0))
    wo, _ = normalize(prev2 - prev)
    wi, dist = normalize(cur - prev)
    bsdf = scene.bsdf(*(slot_rows(a, rows, j - 1) for a in (paths.mat, paths.ns, paths.ng, paths.p)))
    return bsdf.pdf(wo, wi) * np.abs(dot(slot_rows(paths.ng, rows, j), wi)) / np.maximum(dist * dist, 1e-300)


def _light_vertex_pdf(scene: BuiltScene, paths: PathBatch, rows: NDArray) -> NDArray:
    """Density of the light vertex x_k as sampled by ``illuminate`` from x_{k−1}, in the
    vertex's own measure: area (area lights, emissive triangles), counting (point, sun)
    or solid angle (environment: the density of the direction stored in slot k); the
    light-selection pmf included."""
    k = paths.k[rows]
    return scene.lights.pdf_illuminate_vertex(paths.light[rows], slot_rows(paths.p, rows, k - 1),
                                              slot_rows(paths.p, rows, k))


def bidirectional_mutation(ctx: MutationContext, x: PathBatch, rng: np.random.Generator) -> Proposal:
    """Replace x2 … x_{m−1} (and possibly the light vertex) by a new BSDF-sampled subpath."""
    scene = ctx.scene
    lights = scene.lights
    n, K = len(x), x.slots
    L = ctx.max_edges
    k = x.k
    m = 3 + np.minimum((rng.random(n) * (k - 1)).astype(np.int64), k - 2)   # uniform in {3..k+1}
    to_light = m == k + 1
    kd = np.where(to_light, k - 1, m - 1)
    lo = np.where(to_light, 1, 2)
    hi = np.where(to_light, L - 1, kd + L - k)
    table = two_tailed_geometric(kd, lo, hi, L + 1)
    cdf = np.cumsum(table, axis=1)
    ka = np.minimum((cdf < rng.random(n)[:, None]).sum(axis=1), L)
    p_ka = table[np.arange(n), ka]
    back = two_tailed_geometric(ka, lo, hi, L + 1)
    p_kd = back[np.arange(n), kd]
    k_new = np.where(to_light, ka + 1, k - kd + ka)
    valid = (p_ka > 0) & (k_new <= L) & (k_new >= 2)
    y = PathBatch.empty(n, K)
    y.raster[:] = x.raster
    y.p[:, :2], y.ng[:, :2], y.ns[:, :2], y.mat[:, :2] = x.p[:, :2], x.ng[:, :2], x.ns[:, :2], x.mat[:, :2]
    y.k[:] = np.where(valid, k_new, 2)
    y.light[:] = x.light
    # Random walk of ka − 1 new vertices from x1 (slots 2 … ka).
    p_new = np.ones(n)
    cur_wo, _ = normalize(x.p[:, 0] - x.p[:, 1])
    for j in range(2, L + 1):
        act = valid & (j <= ka)
        if not act.any():
            break
        r = np.flatnonzero(act)
        mat, ns, ng, pj = (slot_rows(a, r, j - 1) for a in (y.mat, y.ns, y.ng, y.p))
        bsdf = scene.bsdf(mat, ns, ng, pj)
        bs = bsdf.sample(take_rows(cur_wo, r), rng.random((len(r), 3)))
        o = scene.tracer.offset(slot_rows(y.p, r, j - 1), ng, bs.wi)
        surf = scene.intersect(o, bs.wi)
        # A delta event (mirror, glass) is a failed proposal: the chains live on paths
        # without delta vertices (ERCUTS path-traces the others, integrator docstring)
        ok = bs.valid & ~bs.is_delta & surf.valid & (bs.pdf > 0)
        valid[r[~ok]] = False
        r, bs_pdf, wi = r[ok], bs.pdf[ok], bs.wi[ok]
        s = surf.subset(np.flatnonzero(ok))
        _set_vertex(y, r, j, s.p, s.ng, s.ns, s.mat)
        p_new[r] *= bs_pdf * np.abs(dot(s.ng, wi)) / np.maximum(s.t * s.t, 1e-300)
        cur_wo[r] = -wi
    # Close the gap: connect to the kept suffix, or sample a new light vertex.
    keep = valid & ~to_light
    if keep.any():
        r = np.flatnonzero(keep)
        slots = np.arange(K)[None, :]
        src = slots - (ka[r] + 1)[:, None] + m[r][:, None]
        use = (slots >= (ka[r] + 1)[:, None]) & (slots <= y.k[r][:, None])
        src = np.clip(src, 0, K - 1)
        for name in ("p", "ng", "ns"):
            arr, old = getattr(y, name), getattr(x, name)
            arr[r] = np.where(use[:, :, None], np.take_along_axis(old[r], src[:, :, None], axis=1), arr[r])
        y.mat[r] = np.where(use, np.take_along_axis(x.mat[r], src, axis=1), y.mat[r])
    new_light = valid & to_light
    if new_light.any():
        r = np.flatnonzero(new_light)
        last = ka[r]                       # slot of the vertex that connects to the light
        xl = y.p[r, last]
        ls = lights.illuminate(xl, rng.random(len(r)), rng.random((len(r), 2)))
        kind = lights.kind[ls.light]
        ok = ls.valid
        infinite = (kind == SUN) | (kind == ENV)
        lp = np.where(infinite[:, None], ls.wi, lights.chain_vertex(ls.light, ls.p))
        y.light[r] = ls.light
        slot = y.k[r]
        y.p[r, slot] = lp
        y.ng[r, slot] = np.where(((kind == AREA) | (kind == TRI))[:, None], ls.n, 0.0)
        y.ns[r, slot] = y.ng[r, slot]
        p_new[r] *= _light_vertex_pdf(scene, y, r)
        valid[r[~ok]] = False
    r = np.flatnonzero(valid & (y.k >= 3))            # the new x2 scatters: not on mirrors, glass
    valid[r[~_x1_allowed(ctx, y, r, 2)]] = False
    # Visibility of the connecting edge (slot ka → ka+1).
    r = np.flatnonzero(valid)
    if len(r):
        vis = edge_visible(scene, y.take(r), ka[r])
        valid[r[~vis]] = False
    # Reverse density: the old vertices x2 … x_{m−1} (and the old light vertex).
    p_old = np.ones(n)
    for j in range(2, K):
        act = valid & (j < np.where(to_light, k, m))
        if not act.any():
            break
        r = np.flatnonzero(act)
        p_old[r] *= _walk_pdf(scene, x, r, np.full(len(r), j))
    r = np.flatnonzero(valid & to_light)
    if len(r):
        p_old[r] *= _light_vertex_pdf(scene, x, r)
    sel_x = 1.0 / np.maximum(k - 1, 1)
    sel_y = 1.0 / np.maximum(y.k - 1, 1)
    num = sel_y * p_kd * p_old
    den = sel_x * p_ka * p_new
    ratio = np.where(valid & (den > 0), num / np.where(den > 0, den, 1.0), 0.0)
    valid &= np.isfinite(ratio)
    return Proposal(y, np.where(valid, ratio, 0.0), valid, np.ones(n, bool))


def multichain_perturbation(ctx: MutationContext, x: PathBatch, rng: np.random.Generator) -> Proposal:
    """Never applicable: the material model has no specular (delta) chains."""
    n = len(x)
    return Proposal(x.copy(), np.zeros(n), np.zeros(n, bool), np.zeros(n, bool))


MUTATORS = {LENS: lens_perturbation, CAUSTIC: caustic_perturbation,
            MULTICHAIN: multichain_perturbation, BIDIR: bidirectional_mutation}


def applicable(ctx: MutationContext, x: PathBatch, enabled: tuple[bool, bool, bool, bool]) -> NDArray:
    """(C, 4) which mutations apply to each path (enabled ∧ structurally possible)."""
    n = len(x)
    out = np.zeros((n, 4), bool)
    out[:, LENS] = enabled[LENS]
    out[:, CAUSTIC] = enabled[CAUSTIC] and not ctx.scene.camera.ortho
    out[:, MULTICHAIN] = False          # no delta lobes → never two specular chains
    out[:, BIDIR] = enabled[BIDIR]
    return out
