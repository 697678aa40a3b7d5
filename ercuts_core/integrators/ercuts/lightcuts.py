"""Lightcuts over the Ercuts light tree (Ercuts step 5), batched over shading points.

Zhu, Xu, Pan 2010, §3.5, following Walter et al. 2005 ("Lightcuts: a scalable approach to
illumination", SIGGRAPH 2005): the radiance at x toward ω from N VPLs,

    L(x, ω) = Σ_i M_i G_i V_i I_i,   M_i = f(x, ω, ω_i)·cos θ_x,   G_i = max(0, n_i·(−ω_i))/d_i²,

with cos θ_x = max(0, n_x·ω_i) (|n_x·ω_i| at points flagged transmissive, so the bound
and the estimate always see the same hemispheres), is approximated on a *cut* of the
light tree: a cluster C with representative r contributes ``M_r G_r V_r I_C`` (RGB).
Its error is bounded by
``L̄_C = cosbound(x, n_x, box_C) · Ḡ_C · Y(f̄_x ⊙ I_C)`` (V̄ = 1; shared docs algorithm.md
§E.2 (a)–(c)); leaves are exact.  At glossy receivers (:class:`GlossyReceivers`) the
material factor cosbound·f̄_x is a per-cluster bound of the GGX lobe instead (the lobe's
peak f̄_x is exceeded there, up to ∝ 1/(n·wo) at grazing angles), and at rough glass
receivers of its reflection and transmission lobes (Walter et al. 2007;
:func:`ercuts_core.bsdf.rough_glass_cosine_bound`: the lobe at normal incidence was exceeded
×10³ toward the reflection peak at grazing views and ×1.5 on the transmission side,
tests/test_rough_glass_bound.py).  Starting from the root, every cut node whose bound
exceeds ``max_error`` × (the point's current total estimate) is replaced by its two
children (Weber's law, 2 %), until no node qualifies or the cut holds ``max_cut_size``
nodes.  The child that shares its parent's representative reuses M·G·V (scaled by
I_child / I_C, no ray); the other child costs one evaluation and one shadow ray.

Batching (algorithm.md §G.6): all points refine in lock-step rounds over flat arrays
(point index, node id, M·G·V, bound); each round sends all its new shadow rays through
one ``visible`` call.  There is no Python loop over points or nodes, only over rounds.
In a round a point refines its qualifying nodes whose error is within a factor 4 of
its largest one (a batched version of Walter's max-error-first order; it matters when
the cut-size cap binds, where refining every qualifying node at once wastes the budget
on mid-sized nodes: 12 % instead of 2.5 % mean error at a cap of 100 in the benchmark
room).  Rounds stop when no node qualifies, so every final node satisfies the
criterion unless the cap is reached.  Cut entries whose bound is 0 (leaves, clusters
below the receiver's horizon or facing away) are exact and leave the working set.

Optional G clamp (algorithm.md §D.4): ``G = min(G, clamp)`` in the evaluations *and* the
bounds (Ḡ ≤ clamp); the energy removed by the clamp is reported.

Units: positions in scene units, intensities in W/sr (RGB), BSDF values in 1/sr, radiance
in W·sr⁻¹·m⁻²; luminance Y = 0.2126 R + 0.7152 G + 0.0722 B drives every comparison.
"""
from __future__ import annotations

from dataclasses import dataclass, fields
from typing import Callable

import numpy as np
from numpy.typing import NDArray

from ... import kernels
from ...arrays import take_rows
from ...bsdf import (COS_EPS, Bsdf, ggx_cosine_bound, refracted_direction,
                     rough_glass_cosine_bound)
from ...sampling import INV_PI
from ...vecmath import dot
from ...kernels import bounds as kernel_bounds
from ...kernels import refine
from .cut_rounds import run_rounds
from .light_tree import LightTree, luminance

#: Pair budget of one brute-force block (memory ≈ 200 B per pair; the cancel is polled after
#: each: 2^20 pairs took up to 2.9 s on the loaded 2-core machine, 2^18 ≈ 0.7 s).
_BRUTE_BLOCK = 1 << 18
#: Squared-distance floor that keeps a light sitting on a shading point finite.
_D2_MIN = 1e-30
#: Refinement criteria of :func:`lightcut`.
_MODES = ("bound", "literal", "total")
#: Per-round selection band: a point refines only nodes with err ≥ _BAND·(its max err).
_BAND = 0.25

EvalF = Callable[[NDArray, NDArray], NDArray]
Visible = Callable[[NDArray, NDArray, NDArray], NDArray]


@dataclass
class GlossyReceivers:
    """The GGX lobes of the glossy points of a :class:`ShadingPoints` batch (per point,
    aligned with its P points), for the per-cluster material bound of :func:`cluster_bound`.

    At a point with ``mask`` True the material term M = f(wo, wi)·cos θ_x is bounded over a
    cluster box B by

        M̄ = (kd/π)·cosbound(x, n, B)  +  [cosbound(x, n, B) > 0] · max(F0, F90) ·
             D(√((1 + cosbound(x, r, B))/2)) · G1(wo) / (4 n·wo)

    (:func:`ercuts_core.bsdf.ggx_cosine_bound`; r = 2(n·wo)n − wo the mirror direction).
    The diffuse part is exact as before; the specular part uses the receiver cosine to
    cancel the 1/(n·wi) of the microfacet BRDF, which holds because the point's lightcut
    normal ``ShadingPoints.n`` is the lobe's shading normal (``mask`` is False
    otherwise; those points keep the constant ``f_bound``).

    Points with a rough glass lobe (``glass``; Walter et al. 2007) add its reflection and
    transmission bounds (:func:`ercuts_core.bsdf.rough_glass_cosine_bound`), each only where
    the box reaches its side of the surface, with n the lobe's normal flipped to wo's side:

        M̄ += [cosbound(x, n, B) > 0]·kr·refl + [cosbound(x, −n, B) > 0]·kt·trans,

    with the four box cosines wo·wi ∈ [−scb(x, −wo, B), scb(x, wo, B)], scb(x, r, B) and
    scb(x, t, B) (scb = :func:`signed_cosine_bound`, which may be negative; t the refraction
    of wo about n).  The receiver
    cosine |n·wi| of a transmissive point (``ShadingPoints.transmissive``) cancels the
    1/|n·wi| of both lobes; at a point that is not transmissive (only max(0, n_x·wi) counts)
    the same M̄ still bounds M.  The diffuse and opaque specular parts of such a point (a
    partly transmitting Principled BSDF) use the upper side cosbound(x, n, B).

    A translucent lobe (``kdt_pi``: Cycles' Translucent BSDF, kdt/π for wi on the far side)
    adds (kdt/π)·cosbound(x, −n, B) at rough glass points and (kdt/π)·cb at the others, cb
    the receiver cosine bound (both sides: translucent points are ``transmissive``).

    Attributes:
        mask: (P,) bool, points whose per-cluster bound is used.
        r: (P,3) unit mirror directions of wo about the lobe's normal.
        kd_pi: (P,3) diffuse part kd/π [1/sr].
        spec: (P,3) max(F0, F90) (0 where n·wo ≤ COS_EPS: no specular light at all).
        cos_o: (P,) n·wo.
        alpha: (P,) GGX alpha.
        glass: (P,) bool, points of ``mask`` with a rough glass lobe (None: no such point).
        ns: (P,3) the lobe's unit normal flipped to wo's side (glass points; else unused).
        wo: (P,3) unit outgoing directions (glass points).
        t: (P,3) unit refraction of wo about ``ns`` (−ns where wo is beyond the critical
            angle; then unused).
        eta: (P,) relative index η' = η_t/η_i of the glass lobe for this wo.
        kr: (P,) glass reflection weight (1 − m)·t (0 where n·wo ≤ COS_EPS).
        kt: (P,3) glass transmission weight (1 − m)·t·base (0 where n·wo ≤ COS_EPS).
        kdt_pi: (P,3) translucent part kdt/π [1/sr] (None: no point has one).
    """

    mask: NDArray
    r: NDArray
    kd_pi: NDArray
    spec: NDArray
    cos_o: NDArray
    alpha: NDArray
    glass: NDArray | None = None
    ns: NDArray | None = None
    wo: NDArray | None = None
    t: NDArray | None = None
    eta: NDArray | None = None
    kr: NDArray | None = None
    kt: NDArray | None = None
    kdt_pi: NDArray | None = None

    @classmethod
    def from_bsdf(cls, bsdf: Bsdf, wo: NDArray, n: NDArray) -> GlossyReceivers:
        """The glossy lobes of P points with the :class:`~ercuts_core.bsdf.Bsdf` ``bsdf``
        (P lanes), outgoing directions ``wo`` and lightcut normals ``n`` (P,3).

        A point is in ``mask`` when its lobe is specular and ``n`` is the lobe's normal
        flipped to the side of wo (as in the G-buffer).  Where ``n`` is the opposite of the
        lobe's normal, f·max(0, n·wi) = 0 for every wi and the specular bound is 0 (at a
        point without a glass lobe; with one, the glass bound covers both sides).
        """
        wo = np.asarray(wo, np.float64).reshape(-1, 3)
        n = np.asarray(n, np.float64).reshape(-1, 3)
        sign = np.where(dot(wo, bsdf.ng) < 0.0, -1.0, 1.0)
        ns = bsdf.ns * sign[:, None]                     # the normal of Bsdf._eval_pdf
        align = dot(ns, n)
        cos_o = dot(wo, ns)
        # (a delta lobe is not a receiver: only its continuous part, the diffuse, is gathered)
        aligned = ~bsdf.is_diffuse & ~bsdf.delta & (np.abs(align) >= 1.0 - 1e-12)   # up to rounding
        has_glass = aligned & (bsdf.p_tr > 0.0)
        mask = aligned & (bsdf.p_tr <= 0.0)
        lit = mask & (align > 0.0) & (cos_o > COS_EPS)
        spec = np.where(lit[:, None], np.maximum(bsdf.f0, bsdf.f90), 0.0)
        r = 2.0 * cos_o[:, None] * ns - wo
        alpha = np.asarray(bsdf.alpha, np.float64)
        kdt_pi = bsdf.kdt * INV_PI if bsdf.has_translucent else None
        if not has_glass.any():
            return cls(mask, r, bsdf.kd * INV_PI, spec, cos_o, alpha, kdt_pi=kdt_pi)
        # Rough glass points: both sides of the surface count (bounds per side)
        lit_g = has_glass & (cos_o > COS_EPS)
        spec = np.where(lit_g[:, None], np.maximum(bsdf.f0, bsdf.f90), spec)
        eta = bsdf.eta_rel(wo)
        t, _ = refracted_direction(wo, ns, eta)
        return cls(mask | has_glass, r, bsdf.kd * INV_PI, spec, cos_o, alpha, glass=has_glass,
                   ns=ns, wo=wo, t=t, eta=eta, kr=np.where(lit_g, bsdf.kr, 0.0),
                   kt=np.where(lit_g[:, None], bsdf.kt, 0.0), kdt_pi=kdt_pi)

    def subset(self, idx: NDArray) -> GlossyReceivers:
        """The points ``idx`` (rows of every array field)."""
        return GlossyReceivers(*(None if getattr(self, f.name) is None
                                 else np.asarray(getattr(self, f.name))[idx] for f in fields(self)))


@dataclass
class ShadingPoints:
    """A batch of P shading points plus the callbacks that hide scene and BSDF code.

    Attributes:
        p: (P, 3) positions.
        n: (P, 3) unit shading normals, oriented toward the ``wo`` side.
        wo: (P, 3) unit outgoing directions.
        f_bound: (P, 3) per-channel upper bound of the BSDF value over all directions
            (diffuse: albedo/π) [1/sr].
        eval_f: ``eval_f(idx (K,), wi (K,3)) -> (K,3)`` BSDF value f(x_idx, wo_idx, wi),
            without the cosine.
        visible: ``visible(idx (K,), q (K,3), qn (K,3)) -> (K,) bool``: is the segment from
            point idx to the light at q (normal qn) free?  Called once per round.
        transmissive: optional (P,) bool.  Where True, light from below the surface
            counts with |cos θ_x|; elsewhere only the upper hemisphere counts
            (max(0, cos θ_x)), and the bound uses the matching hemisphere(s).
        glossy: optional :class:`GlossyReceivers`: at its points, the material bound is
            computed per cluster (the GGX lobe's bound over the cluster's directions)
            instead of the constant ``f_bound``, which is not a bound for glossy lobes.
    """

    p: NDArray
    n: NDArray
    wo: NDArray
    f_bound: NDArray
    eval_f: EvalF
    visible: Visible
    transmissive: NDArray | None = None
    glossy: GlossyReceivers | None = None

    @property
    def count(self) -> int:
        """Number of points P."""
        return int(np.shape(self.p)[0])


@dataclass
class LightcutResult:
    """Output of :func:`lightcut`.

    Attributes:
        radiance: (P, 3) estimated outgoing radiance.
        cut_size: (P,) int final cut size per point.
        clamped_energy: Σ over points and final cut nodes of Y(energy removed by the G
            clamp), scaled like the estimate (M_r·V_r·(G_r − min(G_r, clamp))·I_C).
        shadow_rays: number of shadow rays traced (root evaluations included).
        rounds: number of refinement rounds (not counting the root evaluation).
        cut_point, cut_node: (C,) final cut entries (point index, node id), only with
            ``return_cut=True`` (else None); C = cut_size.sum().
        cut_estimate: (C,3) RGB estimate M_r·G_r·V_r·I_C of each entry (or None).
        cut_bound: (C,) luminance error bound L̄_C of each entry (or None).
        unmet: (P,) bool, the point's cut stopped (``max_cut_size`` or ``on_round``) before
            its stopping rule held: its error is *not* bounded by ``max_error`` (reported as
            ``cut_bound_unmet`` so a "2 %" that was not reached says so).
    """

    radiance: NDArray
    cut_size: NDArray
    clamped_energy: float
    shadow_rays: int
    rounds: int
    cut_point: NDArray | None = None
    cut_node: NDArray | None = None
    cut_estimate: NDArray | None = None
    cut_bound: NDArray | None = None
    unmet: NDArray | None = None


# ------------------------------------------------------------------------------ bounds



def _frame(n: NDArray) -> tuple[NDArray, NDArray]:
    """Two unit tangents (K,3) completing unit vectors n (K,3) (Duff et al. 2017)."""
    sign = np.where(n[:, 2] >= 0.0, 1.0, -1.0)
    a = -1.0 / (sign + n[:, 2])
    b = n[:, 0] * n[:, 1] * a
    t = np.stack([1.0 + sign * n[:, 0] ** 2 * a, sign * b, -sign * n[:, 0]], axis=1)
    s = np.stack([b, sign + n[:, 1] ** 2 * a, -n[:, 1]], axis=1)
    return t, s


def _range_along(d: NDArray, lo: NDArray, hi: NDArray) -> tuple[NDArray, NDArray]:
    """Exact (min, max) of d·v over boxes v ∈ [lo, hi]; all (K,3) → (K,), (K,)."""
    a, b = d * lo, d * hi
    return _rowsum3(np.minimum(a, b)), _rowsum3(np.maximum(a, b))


def _rowsum3(v: NDArray) -> NDArray:
    """(K,) v[:, 0] + v[:, 1] + v[:, 2]: the same sum as v.sum(axis=1), several times faster."""
    return v[:, 0] + v[:, 1] + v[:, 2]


def _min_abs(lo: NDArray, hi: NDArray) -> NDArray:
    """Smallest |v| over the interval [lo, hi] (K,)."""
    return np.where((lo <= 0.0) & (hi >= 0.0), 0.0, np.minimum(np.abs(lo), np.abs(hi)))


def cosine_bound(x: NDArray, axis: NDArray, bmin: NDArray, bmax: NDArray) -> NDArray:
    """Upper bound (K,) in [0, 1] of max(0, cos∠(axis, y − x)) over y ∈ [bmin, bmax].

    Walter et al. 2005 box-in-axis-frame bound (algorithm.md §E.2(a)); conservative.
    All inputs are (K,3) (``x`` may broadcast).
    """
    lo, hi = bmin - x, bmax - x
    t, s = _frame(axis)
    _, zmax = _range_along(axis, lo, hi)
    ax = _min_abs(*_range_along(t, lo, hi))
    ay = _min_abs(*_range_along(s, lo, hi))
    den = np.sqrt(ax * ax + ay * ay + zmax * zmax)
    return np.where(zmax > 0.0, zmax / np.where(den > 0.0, den, 1.0), 0.0)


def signed_cosine_bound(x: NDArray, axis: NDArray, bmin: NDArray, bmax: NDArray) -> NDArray:
    """Upper bound (K,) in [−1, 1] of cos∠(axis, y − x) over y ∈ [bmin, bmax], negative when
    the whole box lies behind the plane ⊥ axis (where :func:`cosine_bound` says 0).

    With v = y − x = z·axis + (tangential part ρ): z ≤ z_max over the box.  z_max > 0:
    :func:`cosine_bound`'s value.  z_max < 0: z/√(z² + ρ²) increases with z and with ρ, so
    cos ≤ z_max/√(z_max² + b_x² + b_y²), b = the largest |tangential| components over the
    box.  All inputs (K,3) (``x`` may broadcast).
    """
    lo, hi = bmin - x, bmax - x
    t, s = _frame(axis)
    _, zmax = _range_along(axis, lo, hi)
    xlo, xhi = _range_along(t, lo, hi)
    ylo, yhi = _range_along(s, lo, hi)
    ax, ay = _min_abs(xlo, xhi), _min_abs(ylo, yhi)
    den = np.sqrt(ax * ax + ay * ay + zmax * zmax)
    bx = np.maximum(np.abs(xlo), np.abs(xhi))
    by = np.maximum(np.abs(ylo), np.abs(yhi))
    far = np.sqrt(bx * bx + by * by + zmax * zmax)
    pos = zmax / np.where(den > 0.0, den, 1.0)
    neg = zmax / np.where(far > 0.0, far, 1.0)
    return np.where(zmax > 0.0, pos, np.where(zmax < 0.0, neg, 0.0))


def geometry_bound(x: NDArray, bmin: NDArray, bmax: NDArray, cone_axis: NDArray,
                   cone_cos: NDArray, clamp: float = 0.0) -> NDArray:
    """Upper bound Ḡ (K,) of max(0, n_i·(x − y_i)/|x − y_i|)/|x − y_i|² over a cluster.

    The cluster's lights lie in the box [bmin, bmax] and their normals in the cone
    (axis, cos β).  θ_min bounds the angle between the axis and x − y from below;
    Ḡ = cos(max(0, θ_min − β)) / d²_min, 0 if θ_min − β ≥ π/2, ∞ if x is in the box
    (algorithm.md §E.2(c)).  With ``clamp > 0``, Ḡ ≤ clamp.
    """
    x = np.broadcast_to(x, bmin.shape)
    d2 = _rowsum3((x - np.clip(x, bmin, bmax)) ** 2)
    c = cosine_bound(np.zeros_like(bmin), cone_axis, x - bmax, x - bmin)
    s = np.sqrt(np.maximum(0.0, 1.0 - c * c))
    cb = np.clip(cone_cos, -1.0, 1.0)
    sb = np.sqrt(np.maximum(0.0, 1.0 - cb * cb))
    cos_min = np.where(c >= cb, 1.0, np.maximum(0.0, c * cb + s * sb))
    with np.errstate(divide="ignore"):
        g = np.where(cos_min > 0.0, cos_min / np.where(cos_min > 0.0, d2, 1.0), 0.0)
    return np.minimum(g, clamp) if clamp > 0.0 else g


def _receiver_cos_bound(pts: ShadingPoints, pidx: NDArray, bmin: NDArray,
                        bmax: NDArray) -> NDArray:
    """Bound (K,) of the receiver cosine term over the boxes (both sides if transmissive)."""
    x, n = take_rows(pts.p, pidx), take_rows(pts.n, pidx)
    cb = cosine_bound(x, n, bmin, bmax)
    if pts.transmissive is not None and np.any(pts.transmissive[pidx]):
        tr = np.asarray(pts.transmissive, bool)[pidx]
        cb = np.where(tr, np.maximum(cb, cosine_bound(x, -n, bmin, bmax)), cb)
    return cb


def _glossy_material_bound(pts: ShadingPoints, pidx: NDArray, bmin: NDArray, bmax: NDArray,
                           cb: NDArray, inten: NDArray, m: NDArray) -> NDArray:
    """``m`` (K,) with the entries at glossy points replaced by Y(M̄ ⊙ I_C), M̄ the
    per-cluster material bound of :class:`GlossyReceivers` (only those entries computed;
    rough glass points by :func:`_glass_material_bound`)."""
    gl = pts.glossy
    sel = np.asarray(gl.mask, bool)[pidx]
    kg = np.zeros(0, np.int64)
    if gl.glass is not None:
        glass = np.asarray(gl.glass, bool)[pidx]
        kg, sel = np.flatnonzero(glass), sel & ~glass
    k = np.flatnonzero(sel)
    if k.size == 0 and kg.size == 0:
        return m
    m = m.copy()
    if k.size:
        q = pidx[k]
        cos_r = cosine_bound(take_rows(pts.p, q), take_rows(gl.r, q), bmin[k], bmax[k])
        s = ggx_cosine_bound(gl.cos_o[q], gl.alpha[q], cos_r)
        s = np.where(cb[k] > 0.0, s, 0.0)
        mb = cb[k, None] * take_rows(gl.kd_pi, q) + s[:, None] * take_rows(gl.spec, q)
        if gl.kdt_pi is not None:       # translucent: cb covers both sides (transmissive)
            mb = mb + cb[k, None] * take_rows(gl.kdt_pi, q)
        m[k] = luminance(mb * inten[k])
    if kg.size:
        m[kg] = luminance(_glass_material_bound(gl, take_rows(pts.p, pidx[kg]), pidx[kg], bmin[kg],
                                                bmax[kg]) * inten[kg])
    return m


def _glass_material_bound(gl: GlossyReceivers, x: NDArray, q: NDArray, bmin: NDArray,
                          bmax: NDArray) -> NDArray:
    """M̄ (K,3) [1/sr] of rough glass points ``q`` (K,) at positions x (K,3) over the boxes
    [bmin, bmax] (K,3): the sum in :class:`GlossyReceivers` (diffuse, opaque specular, glass
    reflection on the side of ``ns``, glass transmission and translucency on the other side)."""
    n, wo = take_rows(gl.ns, q), take_rows(gl.wo, q)
    cb_up = cosine_bound(x, n, bmin, bmax)
    cb_dn = cosine_bound(x, -n, bmin, bmax)
    w_max = signed_cosine_bound(x, wo, bmin, bmax)
    w_min = -signed_cosine_bound(x, -wo, bmin, bmax)
    cos_r = signed_cosine_bound(x, take_rows(gl.r, q), bmin, bmax)
    cos_t = signed_cosine_bound(x, take_rows(gl.t, q), bmin, bmax)
    cos_o, alpha = gl.cos_o[q], gl.alpha[q]
    refl, trans = rough_glass_cosine_bound(cos_o, alpha, gl.eta[q], w_min, w_max, cos_r, cos_t)
    up = cb_up > 0.0
    s = np.where(up, ggx_cosine_bound(cos_o, alpha, cos_r), 0.0)
    refl = np.where(up, refl, 0.0)
    trans = np.where(cb_dn > 0.0, trans, 0.0)
    mb = (cb_up[:, None] * take_rows(gl.kd_pi, q) + s[:, None] * take_rows(gl.spec, q)
          + (refl * gl.kr[q])[:, None] + trans[:, None] * take_rows(gl.kt, q))
    if gl.kdt_pi is not None:
        mb = mb + cb_dn[:, None] * take_rows(gl.kdt_pi, q)
    return mb


def cluster_bound(tree: LightTree, node: NDArray, pts: ShadingPoints, pidx: NDArray,
                  clamp: float = 0.0) -> NDArray:
    """Luminance error bound L̄_C (K,) of cut entries (point pidx, node); 0 for leaves.

    L̄_C = cosbound(x, n_x, box_C) · Ḡ_C · Y(f̄_x ⊙ I_C).  The per-channel product
    bounds Y(f ⊙ I_C) for any BSDF value f ≤ f̄ (it equals Y(f̄)·Y(I_C) for grey f̄).
    At the glossy points of ``pts.glossy`` the material factor cosbound·f̄ is replaced by
    the per-pair bound M̄ of :class:`GlossyReceivers` (L̄_C = Ḡ_C · Y(M̄ ⊙ I_C)).
    """
    if kernels.enabled():
        return _cluster_bound_compiled(tree, node, pts, pidx, clamp)
    bmin, bmax = take_rows(tree.bmin, node), take_rows(tree.bmax, node)
    cb = _receiver_cos_bound(pts, pidx, bmin, bmax)
    inten = take_rows(tree.intensity, node)
    m = cb * luminance(take_rows(pts.f_bound, pidx) * inten)
    if pts.glossy is not None:
        m = _glossy_material_bound(pts, pidx, bmin, bmax, cb, inten, m)
    m = np.where(take_rows(tree.is_leaf, node), 0.0, m)
    g = geometry_bound(take_rows(pts.p, pidx), bmin, bmax, take_rows(tree.cone_axis, node),
                       take_rows(tree.cone_cos, node), clamp)
    return m * np.where(m > 0.0, g, 0.0)


def _cluster_bound_compiled(tree: LightTree, node: NDArray, pts: ShadingPoints, pidx: NDArray,
                            clamp: float) -> NDArray:
    """:func:`cluster_bound` by :func:`ercuts_core.kernels.bounds.cluster_bounds` (one pass
    per entry); glossy entries are then recomputed with their per-cluster material bound
    (rough glass entries by :func:`ercuts_core.kernels.bounds.glass_bounds`, the others with
    numpy)."""
    node = np.asarray(node, np.int64)
    pidx = np.asarray(pidx, np.int64)
    bound, cb = kernel_bounds.cluster_bounds(pidx, node, *_point_arrays(pts), *_tree_arrays(tree),
                                             float(clamp))
    gl = pts.glossy
    if gl is None:
        return bound
    sel = np.asarray(gl.mask, bool)[pidx]
    if gl.glass is not None:
        glass = np.asarray(gl.glass, bool)[pidx]
        sel &= ~glass
        kg = np.flatnonzero(glass)
        if kg.size:
            bound[kg] = kernel_bounds.glass_bounds(pidx[kg], node[kg], *_glass_arrays(pts),
                                                   *_tree_arrays(tree), float(clamp))
    k = np.flatnonzero(sel)
    if k.size == 0:
        return bound
    nk, pk = node[k], pidx[k]
    bmin, bmax, inten = take_rows(tree.bmin, nk), take_rows(tree.bmax, nk), take_rows(tree.intensity, nk)
    m = _glossy_material_bound(pts, pk, bmin, bmax, cb[k], inten, np.zeros(k.size))
    m = np.where(take_rows(tree.is_leaf, nk), 0.0, m)
    g = geometry_bound(take_rows(pts.p, pk), bmin, bmax, take_rows(tree.cone_axis, nk),
                       take_rows(tree.cone_cos, nk), clamp)
    bound[k] = m * np.where(m > 0.0, g, 0.0)
    return bound


def _glass_arrays(pts: ShadingPoints) -> tuple:
    """The arrays of :func:`ercuts_core.kernels.bounds.glass_bounds` (contiguous float64)."""
    gl = pts.glossy
    kdt_pi = np.zeros_like(gl.kd_pi) if gl.kdt_pi is None else gl.kdt_pi
    return tuple(np.ascontiguousarray(a, np.float64) for a in
                 (pts.p, gl.ns, gl.wo, gl.r, gl.t, gl.cos_o, gl.alpha, gl.eta, gl.kd_pi, gl.spec,
                  gl.kr, gl.kt, kdt_pi))


def _point_arrays(pts: ShadingPoints) -> tuple:
    """(p, n, f_bound, transmissive) of ``pts`` as contiguous arrays for the kernels."""
    tr = (np.zeros(pts.count, np.bool_) if pts.transmissive is None
          else np.ascontiguousarray(pts.transmissive, np.bool_))
    return (np.ascontiguousarray(pts.p, np.float64), np.ascontiguousarray(pts.n, np.float64),
            np.ascontiguousarray(pts.f_bound, np.float64), tr)


def _tree_arrays(tree: LightTree) -> tuple:
    """(is_leaf, intensity, bmin, bmax, cone_axis, cone_cos) of ``tree`` for the kernels."""
    return (tree.is_leaf, tree.intensity, tree.bmin, tree.bmax, tree.cone_axis, tree.cone_cos)


# -------------------------------------------------------------------------- evaluation


def evaluate_lights(pts: ShadingPoints, pidx: NDArray, vidx: NDArray, vpl_pos: NDArray,
                    vpl_normal: NDArray, clamp: float = 0.0
                    ) -> tuple[NDArray, NDArray, int]:
    """M·G·V of single VPLs at shading points, one batched ``visible`` call.

    Args:
        pidx, vidx: (K,) point and VPL indices.

    Returns:
        unit: (K,3) f·cos θ_x·min(G, clamp)·V (multiply by an intensity for radiance).
        loss: (K,3) f·cos θ_x·(G − min(G, clamp))·V, the part removed by the clamp.
        rays: number of shadow rays traced (only for pairs with a non-zero M·G).
    """
    x, q, qn = take_rows(pts.p, pidx), take_rows(vpl_pos, vidx), take_rows(vpl_normal, vidx)
    d = q - x
    d2 = np.maximum(_rowsum3(d * d), _D2_MIN)
    wi = d / np.sqrt(d2)[:, None]
    cos_l = np.maximum(0.0, -dot(qn, wi))
    cos_x = dot(pts.n[pidx], wi)
    if pts.transmissive is not None:
        cos_x = np.where(np.asarray(pts.transmissive, bool)[pidx], np.abs(cos_x), cos_x)
    cos_x = np.maximum(cos_x, 0.0)
    g = cos_l / d2
    gc = np.minimum(g, clamp) if clamp > 0.0 else g
    unit = np.zeros((len(pidx), 3))
    loss = np.zeros((len(pidx), 3))
    live = np.flatnonzero((cos_l > 0.0) & (cos_x > 0.0))
    if live.size == 0:
        return unit, loss, 0
    mf = np.asarray(pts.eval_f(pidx[live], wi[live]), np.float64) * cos_x[live, None]
    live_mask = np.any(mf > 0.0, axis=1)
    live, mf = live[live_mask], mf[live_mask]
    if live.size == 0:
        return unit, loss, 0
    vis = np.asarray(pts.visible(pidx[live], q[live], qn[live]), bool)
    mf = mf * vis[:, None]
    unit[live] = mf * gc[live, None]
    loss[live] = mf * (g - gc)[live, None]
    return unit, loss, int(live.size)


def brute_force(vpl_pos: NDArray, vpl_normal: NDArray, vpl_intensity: NDArray,
                pts: ShadingPoints, clamp: float = 0.0, keep_going=None) -> NDArray | None:
    """Exact Σ_i M_i G_i V_i I_i over all VPLs (P,3), in blocks of ≤ 2^18 pairs.

    The ablation baseline and the test oracle; uses the same evaluation (and clamp) as
    :func:`lightcut`.  Loops over blocks only.  ``keep_going()`` (optional) is called after
    every block; False stops and returns None (a batch of 512 points × 5·10⁴ VPLs is
    ~25 blocks, tens of seconds: Esc must not wait for it).
    """
    vpl_pos, vpl_normal, vpl_intensity = (np.asarray(a, np.float64).reshape(-1, 3)
                                          for a in (vpl_pos, vpl_normal, vpl_intensity))
    n_pts, n_vpl = pts.count, len(vpl_pos)
    out = np.zeros((n_pts, 3))
    if n_pts == 0 or n_vpl == 0:
        return out
    vstep = min(n_vpl, _BRUTE_BLOCK)
    pstep = max(1, _BRUTE_BLOCK // vstep)
    for p0 in range(0, n_pts, pstep):
        p1 = min(n_pts, p0 + pstep)
        for v0 in range(0, n_vpl, vstep):
            v1 = min(n_vpl, v0 + vstep)
            pidx = np.repeat(np.arange(p0, p1), v1 - v0)
            vidx = np.tile(np.arange(v0, v1), p1 - p0)
            unit, _, _ = evaluate_lights(pts, pidx, vidx, vpl_pos, vpl_normal, clamp)
            out[p0:p1] += _sum_by(pidx - p0, unit * vpl_intensity[vidx], p1 - p0)
            if keep_going is not None and keep_going() is False:
                return None
    return out


def _sum_by(group: NDArray, values: NDArray, n: int) -> NDArray:
    """Per-group sums (n,3) of (K,3) values."""
    return np.stack([np.bincount(group, values[:, c], n) for c in range(3)], axis=1)


# --------------------------------------------------------------------------- the cut


@dataclass
class _Entries:
    """Active cut entries (flat arrays, K entries)."""

    pt: NDArray       # (K,) point index
    node: NDArray     # (K,) tree node
    unit: NDArray     # (K,3) M·G·V of the node's representative
    loss: NDArray     # (K,3) clamp loss of the representative (same scaling as unit)
    bound: NDArray    # (K,) luminance error bound L̄_C

    @staticmethod
    def empty() -> "_Entries":
        z = np.zeros(0, np.int64)
        return _Entries(z, z, np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0))

    def take(self, idx: NDArray) -> "_Entries":
        return _Entries(*(take_rows(a, idx) for a in (self.pt, self.node, self.unit, self.loss,
                                                      self.bound)))

    @staticmethod
    def cat(parts: list["_Entries"]) -> "_Entries":
        return _Entries(*(np.concatenate([getattr(e, f) for e in parts])
                          for f in ("pt", "node", "unit", "loss", "bound")))


class _Accum:
    """Per-point sums of finished (exact, bound 0) entries."""

    def __init__(self, n_pts: int, keep: bool) -> None:
        self.rad = np.zeros((n_pts, 3))
        self.loss = 0.0
        self.count = np.zeros(n_pts, np.int64)
        self.kept: list[_Entries] | None = [] if keep else None

    def add(self, tree: LightTree, e: _Entries) -> None:
        if self.kept is not None:
            self.kept.append(e)
        inten = take_rows(tree.intensity, e.node)
        n = len(self.count)
        self.rad += _sum_by(e.pt, e.unit * inten, n)
        self.loss += float(luminance(e.loss * inten).sum())
        self.count += np.bincount(e.pt, minlength=n)


def _select(e: _Entries, err: NDArray, thr: NDArray, budget: NDArray, band: float) -> NDArray:
    """Entries to refine this round (indices).

    Candidates have err > thr (K,).  Per point, only the band err ≥ band·max err is
    taken (largest first, at most budget[pt] of them), so a round never spends the cut
    budget on mid-sized nodes while larger children are still to come (an approximation
    of Walter's sequential max-error-first order; band = 0 refines all candidates).
    """
    cand = np.flatnonzero(err > thr)
    if cand.size == 0:
        return cand
    if 0.0 < band <= 1.0:
        # Drop what the band drops before sorting (lexsort dominates the gather otherwise).
        # The dropped entries sort after every kept one of their point, so the ranks and
        # the order of the rest are unchanged.
        top = np.full(len(budget), -np.inf)
        np.maximum.at(top, e.pt[cand], err[cand])
        cand = cand[err[cand] >= band * top[e.pt[cand]]]
    cand = cand[np.lexsort((-err[cand], e.pt[cand]))]
    grp = e.pt[cand]
    first = np.searchsorted(grp, grp, side="left")
    rank = np.arange(cand.size) - first
    keep = rank < budget[grp]
    if band > 0.0:
        top = err[cand[first]]
        keep &= (err[cand] >= band * top) | (rank == 0)     # ∞ tops keep only ∞ entries
    return cand[keep]


def _prefix_threshold(e: _Entries, limit: NDArray) -> NDArray:
    """Thresholds (K,) that select, per point, the fewest largest bounds whose removal
    would bring Σ_C L̄_C (with children at 0) down to ``limit`` (P,)."""
    order = np.lexsort((-e.bound, e.pt))
    grp, inf = e.pt[order], np.isinf(e.bound[order])
    b = np.where(inf, 0.0, e.bound[order])               # ∞ bounds are always refined
    bsum = np.bincount(grp, b, len(limit))
    scale = np.where(bsum > 0.0, bsum, 1.0)
    b = b / scale[grp]                                    # per point Σ b = 1: exact cumsum
    csum = np.cumsum(b)
    first = np.searchsorted(grp, grp, side="left")
    before = csum - b - (csum[first] - b[first])          # Σ of larger bounds, same point
    excess = (bsum - limit) / scale
    thr = np.empty(len(b))
    thr[order] = np.where(inf | (before < excess[grp]), -1.0, np.inf)
    return thr


def _criterion(e: _Entries, est: NDArray, total: NDArray, mode: str, max_error: float,
               abs_floor: float) -> tuple[NDArray, NDArray]:
    """Per-entry error (K,) and refinement threshold (K,) of one round.

    ``bound``/``literal``: refine if err_C > max(ε·L̃, floor).  ``total``: a point whose
    Σ_C L̄_C exceeds max(ε/(1+ε)·L̃, floor) refines its largest-bound nodes, as many as
    would be needed if their children were exact (at least one per round).
    """
    if mode == "total":
        limit = np.maximum(max_error / (1.0 + max_error) * total, abs_floor)
        return e.bound, _prefix_threshold(e, limit)
    err = e.bound if mode == "bound" else np.maximum(e.bound - est, 0.0)
    return err, np.maximum(max_error * total, abs_floor)[e.pt]


def _refine(tree: LightTree, e: _Entries, sel: NDArray, pts: ShadingPoints, lights: tuple,
            clamp: float) -> tuple[_Entries, int]:
    """Children entries of the selected entries; one batched evaluation (one visible call)."""
    return _children(tree, take_rows(e.pt, sel), take_rows(e.node, sel), take_rows(e.unit, sel),
                     take_rows(e.loss, sel), pts, lights, clamp)


def _children(tree: LightTree, pidx: NDArray, node: NDArray, unit: NDArray, loss: NDArray,
              pts: ShadingPoints, lights: tuple, clamp: float) -> tuple[_Entries, int]:
    """The children of entries (pidx, node) with their parents' unit and loss (S,): first
    those sharing the parent's representative (same M·G·V, no ray), then the others (one
    batched evaluation and ``visible`` call); with their bounds."""
    lft, rgt = take_rows(tree.left, node), take_rows(tree.right, node)
    same = np.where(take_rows(tree.rep, lft) == take_rows(tree.rep, node), lft, rgt)
    other = lft + rgt - same
    new_unit, new_loss, rays = evaluate_lights(pts, pidx, take_rows(tree.rep, other), *lights, clamp)
    kids = _Entries(np.concatenate([pidx, pidx]), np.concatenate([same, other]),
                    np.concatenate([unit, new_unit]), np.concatenate([loss, new_loss]),
                    np.zeros(2 * len(pidx)))
    kids.bound = cluster_bound(tree, kids.node, pts, kids.pt, clamp)
    return kids, rays


def _retire(tree: LightTree, e: _Entries, acc: _Accum) -> _Entries:
    """Move exact entries (bound 0) into the accumulator; return the rest."""
    done = e.bound <= 0.0
    if np.any(done):
        acc.add(tree, e.take(np.flatnonzero(done)))
        e = e.take(np.flatnonzero(~done))
    return e


def lightcut(tree: LightTree, vpl_pos: NDArray, vpl_normal: NDArray, vpl_intensity: NDArray,
             pts: ShadingPoints, *, max_error: float = 0.02, max_cut_size: int = 1000,
             clamp: float = 0.0, abs_floor: float = 0.0, error_mode: str = "bound",
             return_cut: bool = False, on_round=None) -> LightcutResult:
    """Batched lightcut radiance at P shading points.

    Args:
        tree: light tree built over the same VPLs (``tree.rep`` indexes the VPL arrays).
        vpl_pos, vpl_normal, vpl_intensity: (N,3) VPL positions, unit normals, RGB W/sr
            (cluster intensities come from ``tree.intensity``; ``vpl_intensity`` is only
            checked against it for the leaves).
        pts: the shading points and callbacks.
        max_error: relative threshold (Weber's law, 0.02 in Walter 2005 and Ercuts).
        max_cut_size: maximum cut size per point (≥ 1).
        clamp: G clamp (> 0 enables it) for evaluations and bounds.
        abs_floor: absolute luminance error that never needs refinement (not in the papers;
            keeps black/occluded points from refining to ``max_cut_size``).
        error_mode: ``'bound'``: refine while some L̄_C > ε·L̃ (Walter 2005; every node's
            error is below 2 % of the total, the *sum* of errors is not bounded).
            ``'literal'``: err_C = L̄_C − L_C, the Ercuts text |L̄ − L| < 2 % L applied per
            node (cheaper, not a true error bound; algorithm.md §G.6).  ``'total'``:
            refine (largest bounds first) while Σ_C L̄_C > ε/(1+ε)·L̃, which guarantees
            |L̃ − L| ≤ ε·L in luminance (L = exact sum) unless the cut size cap is hit;
            far more expensive because the bounds are loose.
        return_cut: also return the final cut entries (see :class:`LightcutResult`).
        on_round: optional ``on_round() -> bool | None`` called after every refinement
            round (progress reports); False stops refining: every point keeps its current,
            coarser cut (a complete estimate).

    Returns:
        :class:`LightcutResult`.
    """
    if error_mode not in _MODES:
        raise ValueError(f"error_mode must be one of {_MODES}, not {error_mode!r}")
    lights = tuple(np.asarray(a, np.float64).reshape(-1, 3) for a in (vpl_pos, vpl_normal))
    inten = np.asarray(vpl_intensity, np.float64).reshape(-1, 3)
    if not (len(lights[0]) == len(lights[1]) == len(inten) == tree.n_lights):
        raise ValueError("VPL arrays and light tree disagree on the number of VPLs")
    if not np.allclose(tree.intensity[tree.leaf_node], inten):
        raise ValueError("vpl_intensity differs from the intensities the tree was built with")
    n_pts = pts.count
    acc = _Accum(n_pts, return_cut)
    if n_pts == 0 or tree.root < 0:
        return _result(tree, acc, 0, 0)
    pidx = np.arange(n_pts)
    root = np.full(n_pts, tree.root, np.int64)
    unit, loss, rays = evaluate_lights(pts, pidx, tree.rep[root], *lights, clamp)
    e = _Entries(pidx, root, unit, loss, cluster_bound(tree, root, pts, pidx, clamp))
    if kernels.enabled():
        return _lightcut_compiled(tree, e, pts, lights, rays, max_error=max_error,
                                  max_cut_size=max_cut_size, clamp=clamp, abs_floor=abs_floor,
                                  error_mode=error_mode, return_cut=return_cut, on_round=on_round)
    e = _retire(tree, e, acc)
    rounds = 0
    unmet = np.zeros(n_pts, bool)
    while e.pt.size:
        est = luminance(e.unit * take_rows(tree.intensity, e.node))
        total = luminance(acc.rad) + np.bincount(e.pt, est, n_pts)
        err, thr = _criterion(e, est, total, error_mode, max_error, abs_floor)
        unmet[:] = False
        unmet[e.pt[err > thr]] = True         # refinement wanted: the rule does not hold yet
        budget = max_cut_size - acc.count - np.bincount(e.pt, minlength=n_pts)
        sel = _select(e, err, thr, budget, _BAND)
        if sel.size == 0:
            break
        kids, new_rays = _refine(tree, e, sel, pts, lights, clamp)
        keep = np.ones(e.pt.size, bool)
        keep[sel] = False
        e = _retire(tree, _Entries.cat([e.take(np.flatnonzero(keep)), kids]), acc)
        rays += new_rays
        rounds += 1
        if on_round is not None and on_round() is False:
            break
    else:
        unmet[:] = False                      # every entry retired exact
    acc.add(tree, e)
    res = _result(tree, acc, rays, rounds)
    res.unmet = unmet
    return res


def _lightcut_compiled(tree: LightTree, root: _Entries, pts: ShadingPoints, lights: tuple,
                       rays: int, *, max_error, max_cut_size, clamp, abs_floor, error_mode,
                       return_cut, on_round) -> LightcutResult:
    """The refinement of :func:`lightcut` from the evaluated roots on the compiled kernels
    (:func:`.cut_rounds.run_rounds`; same rounds, cuts and estimates)."""
    def children(pt, node, unit, loss):
        kids, new_rays = _children(tree, pt, node, unit, loss, pts, lights, clamp)
        return kids.node, kids.unit, kids.loss, kids.bound, new_rays

    mode = {"bound": refine.MODE_BOUND, "literal": refine.MODE_LITERAL,
            "total": refine.MODE_TOTAL}[error_mode]
    r = run_rounds(tree, pts.count, root.unit, root.loss, root.bound, children, mode=mode,
                   max_error=max_error, abs_floor=abs_floor, max_cut_size=max_cut_size,
                   band=_BAND, on_round=on_round)
    res = LightcutResult(r.radiance, r.count, r.loss, rays + r.rays, r.rounds, unmet=r.unmet)
    if return_cut:
        res.cut_point, res.cut_node, res.cut_bound = r.pt, r.node, r.bound
        res.cut_estimate = r.unit * tree.intensity[r.node]
    return res


def _result(tree: LightTree, acc: _Accum, rays: int, rounds: int) -> LightcutResult:
    """Pack the accumulator (and the kept cut entries) into a :class:`LightcutResult`."""
    res = LightcutResult(acc.rad, acc.count, acc.loss, rays, rounds)
    if acc.kept is not None:
        cut = _Entries.cat(acc.kept + [_Entries.empty()])
        order = np.argsort(cut.pt, kind="stable")
        cut = cut.take(order)
        res.cut_point, res.cut_node, res.cut_bound = cut.pt, cut.node, cut.bound
        res.cut_estimate = cut.unit * tree.intensity[cut.node]
    return res
