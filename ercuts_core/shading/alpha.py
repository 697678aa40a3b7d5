"""Stochastic transparency (Transparent BSDF / Principled Alpha): a ray that hits a surface
of alpha a < 1 passes through it with probability 1 − a, for camera, bounce and shadow
rays alike (Cycles' transparent-shadow behaviour in expectation).

:class:`AlphaTracer` wraps a :class:`~ercuts_core.tracer.Tracer` only when some material's
program has an ``alpha`` output (otherwise the plain tracer is used untouched). The
pass-through decision uses a hash of the ray and the crossing count, not a random stream,
so renders stay deterministic for a seed and do not depend on batch order. Shadow rays
become closest-hit queries that continue through transparent hits (slower: alpha scenes only).
"""
from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from ..tracer import Hit

#: Crossings after which a ray counts as blocked (Cycles' transparent max bounces is 8 by
#: default; a higher cap keeps stacks of leaves see-through).
MAX_CROSSINGS = 64


def _hash_uniform(o: NDArray, d: NDArray, k: int) -> NDArray:
    """(N,) uniforms in [0, 1) from the float bits of ray origins/directions and crossing k
    (a 64-bit multiply–xorshift mix; splitmix64 constants)."""
    bits = np.ascontiguousarray(np.concatenate([o, d], axis=1), np.float64).view(np.uint64)
    with np.errstate(over="ignore"):           # the multiplies wrap modulo 2⁶⁴ on purpose
        h = np.full(len(o), np.uint64(0x9E3779B97F4A7C15) * np.uint64(k + 1), np.uint64)
        for j in range(6):
            h ^= bits[:, j]
            h *= np.uint64(0xBF58476D1CE4E5B9)
            h ^= h >> np.uint64(31)
            h *= np.uint64(0x94D049BB133111EB)
            h ^= h >> np.uint64(29)
    return (h >> np.uint64(11)).astype(np.float64) * (1.0 / 9007199254740992.0)


class AlphaTracer:
    """A tracer whose hits on alpha-programmed materials are stochastic (module docstring).

    Args:
        tracer: the scene's :class:`~ercuts_core.tracer.Tracer` (delegated to).
        alpha: callable (prim (N,), b (N, 3)) → (N,) alpha in [0, 1] of hits.
        tri_alpha: (T,) bool, True for triangles whose material has an alpha output.
    """

    def __init__(self, tracer, alpha, tri_alpha: NDArray):
        self._tracer = tracer
        self._alpha = alpha
        self._tri_alpha = tri_alpha

    def __getattr__(self, name):
        return getattr(self._tracer, name)

    def intersect(self, o: NDArray, d: NDArray, tmax: NDArray | float | None = None) -> Hit:
        """Closest *opaque* hit along each ray: transparent crossings are skipped."""
        o = np.asarray(o, np.float64)
        d = np.asarray(d, np.float64)
        n = len(o)
        far = np.full(n, np.inf) if tmax is None else \
            np.broadcast_to(np.asarray(tmax, np.float64), (n,)).copy()
        hit = self._tracer.intersect(o, d, None if tmax is None else far)
        todo = np.arange(n)
        for k in range(MAX_CROSSINGS):
            sub = Hit(hit.prim[todo], hit.t[todo], hit.u[todo], hit.v[todo])
            cand = sub.valid & self._tri_alpha[np.maximum(sub.prim, 0)]
            if not cand.any():
                break
            c = np.flatnonzero(cand)
            lanes = todo[c]
            b = np.stack([1.0 - sub.u[c] - sub.v[c], sub.u[c], sub.v[c]], axis=1)
            a = self._alpha(sub.prim[c], b)
            through = _hash_uniform(o[lanes], d[lanes], k) >= a
            lanes = lanes[through]
            if not len(lanes):
                break
            if k == MAX_CROSSINGS - 1:               # give up: the last crossing stays opaque
                break
            # Continue from just past the crossing
            p = o[lanes] + hit.t[lanes][:, None] * d[lanes]
            start = hit.t[lanes] + self._tracer.epsilon(p)        # hit.t: from the original origin
            rest = far[lanes] - start
            nxt = self._tracer.intersect(o[lanes] + start[:, None] * d[lanes], d[lanes],
                                         None if tmax is None else np.maximum(rest, 0.0))
            hit.prim[lanes] = nxt.prim
            hit.u[lanes], hit.v[lanes] = nxt.u, nxt.v
            hit.t[lanes] = np.where(nxt.valid, nxt.t + start, np.inf)
            todo = lanes
        return hit

    def occluded(self, o: NDArray, d: NDArray, tmax: NDArray | float) -> NDArray[np.bool_]:
        """(N,) True where an opaque (after the alpha test) surface blocks the segment."""
        return self.intersect(o, d, tmax).valid

    def visible(self, p0, ng0, p1, ng1):
        """As :meth:`Tracer.visible`, with this tracer's alpha-aware :meth:`occluded`."""
        return type(self._tracer).visible(self, p0, ng0, p1, ng1)
