"""Batched ray queries over embreex (Embree 4), with robust self-intersection offsets.

embreex semantics this module relies on (see shared docs, algorithm.md §F):

* origins/directions must be float32 2-D arrays; distances a float32 1-D array that
  embreex overwrites in place (we always pass a copy);
* ``tnear`` is fixed at 0 and there is no back-face culling, so rays leaving a surface
  must start slightly off it (:meth:`Tracer.offset`);
* ``OCCLUDED`` returns 0 when blocked and −1 when the segment is free;
* ``INTERSECT`` with ``output=True`` returns primID (−1 = miss), u, v, tfar, Ng.

Offsets follow pbrt/Mitsuba's error-bound idea: the origin moves along the geometric
normal by ``eps = max(1e-4·scene_diagonal·2^-7, 64·2^-23·max|p|)``, enough for float32
positions at 1e4 m, and also by ``eps`` along the ray (Mitsuba's ray ``mint``, which
embreex cannot set): a point on an edge shared with another surface — a room's corner,
hit exactly by a camera ray through a pixel centre — is on that surface's plane too, and
the normal offset alone leaves it there, where every ray into the room hits it at t = 0.
Hit positions are recomputed from barycentrics in float64.

Batches are split across threads (embreex ≥ 4.4 releases the GIL while tracing).
"""
from __future__ import annotations

import os
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np
from embreex import rtcore_scene as rtcs
from embreex.mesh_construction import TriangleMesh
from numpy.typing import NDArray

from .vecmath import dot

#: Relative float32 precision used for the position-dependent part of the offset.
_F32_ULP = 2.0**-23
#: Minimum batch size worth splitting over threads.
_THREAD_MIN = 1 << 15


def _f32(a) -> NDArray[np.float32]:
    """``a`` as a contiguous float32 array for embreex. Values beyond float32's range occur
    only in scenes that span ±3e38 m (a sun's emission disk around one lies outside it);
    they become ±inf, and embree reports a miss for such a ray, the only possible answer."""
    with np.errstate(over="ignore"):
        return np.ascontiguousarray(a, np.float32)


@dataclass
class Hit:
    """Closest hits of a ray batch.

    Attributes:
        prim: (N,) int64 triangle index, −1 for misses.
        t: (N,) float64 distance along the unit direction (inf for misses).
        u, v: (N,) float64 barycentrics of vertices 1 and 2 (hit = (1−u−v)·v0 + u·v1 + v·v2).
    """

    prim: NDArray[np.int64]
    t: NDArray[np.float64]
    u: NDArray[np.float64]
    v: NDArray[np.float64]

    @property
    def valid(self) -> NDArray[np.bool_]:
        return self.prim >= 0


class Tracer:
    """Closest-hit and shadow-ray queries on a static triangle mesh.

    Args:
        positions: (V, 3) float32 world-space vertices.
        triangles: (T, 3) int32 indices.
        threads: worker threads per batch (0 = all cores).
    """

    def __init__(self, positions: NDArray, triangles: NDArray, threads: int = 0):
        self.n_triangles = int(len(triangles))
        self._scene = rtcs.EmbreeScene()
        if self.n_triangles:
            TriangleMesh(self._scene, np.ascontiguousarray(positions, np.float32),
                         np.ascontiguousarray(triangles, np.int32))
            # Bounds of the vertices the triangles use: an unused vertex may be anywhere,
            # even NaN/Inf (validate drops the triangles, not the vertices), and an infinite
            # diagonal made every offset infinite.
            used = np.zeros(len(positions), bool)
            used[np.asarray(triangles).reshape(-1)] = True
            p = np.asarray(positions)[used]
            lo, hi = p.min(axis=0).astype(np.float64), p.max(axis=0).astype(np.float64)
            self.diagonal = float(np.linalg.norm(hi - lo))
            # Commit the scene once, single-threaded (lazy commit is not thread-safe).
            self._scene.run(np.zeros((1, 3), np.float32), np.ones((1, 3), np.float32))
        else:
            self.diagonal = 1.0
        self.eps_abs = max(1e-4 * self.diagonal * 2.0**-7, 1e-7)
        self.threads = threads or os.cpu_count() or 1
        self._pool = ThreadPoolExecutor(self.threads) if self.threads > 1 else None
        self.rays_traced = 0

    # ------------------------------------------------------------------ offsets
    def epsilon(self, p: NDArray) -> NDArray:
        """(N,) offset distance for points ``p`` (N, 3): absolute floor + float32 ulp part."""
        a = np.abs(p)
        # max over the 3 columns, elementwise (np.max(axis=-1) is ~20× slower on (N, 3))
        return np.maximum(self.eps_abs, 64.0 * _F32_ULP * np.maximum(np.maximum(a[:, 0], a[:, 1]), a[:, 2]))

    def offset(self, p: NDArray, ng: NDArray, d: NDArray) -> NDArray:
        """Move surface points ``p`` off their surface toward the side ``d`` points to, and
        ``epsilon`` along ``d``, off any other surface through ``p`` (a shared edge).

        Args:
            p: (N, 3) float64 points on triangles.
            ng: (N, 3) unit geometric normals.
            d: (N, 3) unit directions of the rays that leave ``p``.
        Returns:
            (N, 3) float64 ray origins.
        """
        side = np.where(dot(ng, d) >= 0.0, 1.0, -1.0)
        eps = self.epsilon(p)[:, None]
        return p + eps * (side[:, None] * ng + d)

    # ------------------------------------------------------------------ queries
    def _split(self, n: int):
        if self._pool is None or n < _THREAD_MIN:
            return [slice(0, n)]
        k = self.threads
        edges = np.linspace(0, n, k + 1).astype(int)
        return [slice(edges[i], edges[i + 1]) for i in range(k)]

    def _map(self, fn, n: int):
        parts = self._split(n)
        if len(parts) > 1:
            try:
                return list(self._pool.map(fn, parts))
            except RuntimeError:
                # the pool refuses work once the interpreter shuts down (Python runs
                # concurrent.futures' exit hook before atexit handlers, so a viewport render
                # still in flight when Blender quits lands here): trace in this thread
                pass
        return [fn(part) for part in parts]

    def intersect(self, o: NDArray, d: NDArray, tmax: NDArray | float | None = None) -> Hit:
        """Closest hit along rays ``o + t·d`` with 0 < t < tmax (``d`` unit, float64 (N, 3))."""
        n = len(o)
        prim = np.full(n, -1, np.int64)
        t = np.full(n, np.inf)
        u = np.zeros(n)
        v = np.zeros(n)
        if n == 0 or self.n_triangles == 0:
            return Hit(prim, t, u, v)
        o32 = _f32(o)
        d32 = np.ascontiguousarray(d, np.float32)
        far = np.full(n, 1e30, np.float32) if tmax is None else _f32(np.broadcast_to(tmax, (n,))).copy()

        def run(s: slice):
            res = self._scene.run(o32[s], d32[s], dists=far[s].copy(), output=True)
            pid = res["primID"].astype(np.int64)
            hit = pid >= 0
            prim[s] = pid
            t[s] = np.where(hit, res["tfar"], np.inf)
            u[s] = np.where(hit, res["u"], 0.0)
            v[s] = np.where(hit, res["v"], 0.0)

        self._map(run, n)
        self.rays_traced += n
        return Hit(prim, t, u, v)

    def occluded(self, o: NDArray, d: NDArray, tmax: NDArray | float) -> NDArray[np.bool_]:
        """(N,) True where something blocks ``o + t·d`` for 0 < t < tmax."""
        n = len(o)
        blocked = np.zeros(n, bool)
        if n == 0 or self.n_triangles == 0:
            return blocked
        o32 = _f32(o)
        d32 = np.ascontiguousarray(d, np.float32)
        far = _f32(np.broadcast_to(tmax, (n,))).copy()

        def run(s: slice):
            blocked[s] = self._scene.run(o32[s], d32[s], dists=far[s].copy(), query="OCCLUDED") == 0

        self._map(run, n)
        self.rays_traced += n
        return blocked

    def visible(self, p0: NDArray, ng0: NDArray | None, p1: NDArray, ng1: NDArray | None
                ) -> NDArray[np.bool_]:
        """(N,) mutual visibility of point pairs; a None normal means a point not on a surface.

        Both ends are offset off their surfaces toward each other, so the segment test
        neither hits the surfaces it starts and ends on nor skips thin blockers.
        """
        d = p1 - p0
        length = np.sqrt(np.einsum("ij,ij->i", d, d))
        d = d / np.where(length > 0, length, 1.0)[:, None]     # offset() moves eps along a unit d
        o0 = p0 if ng0 is None else self.offset(p0, ng0, d)
        o1 = p1 if ng1 is None else self.offset(p1, ng1, -d)
        seg = o1 - o0
        dist = np.sqrt(dot(seg, seg))
        ok = dist > 0
        if ok.all():  # the usual case: no zero-length segment to guard
            return ~self.occluded(o0, seg / dist[:, None], dist * (1.0 - 1e-6))
        dirs = np.where(ok[:, None], seg / np.where(ok, dist, 1.0)[:, None], 0.0)
        dirs[~ok, 2] = 1.0
        tmax = np.where(ok, dist * (1.0 - 1e-6), 0.0)
        return ~self.occluded(o0, dirs, tmax)

    def close(self) -> None:
        if self._pool is not None:
            self._pool.shutdown(wait=False)
            self._pool = None

    def __del__(self):
        try:
            self.close()
        except Exception:
            pass
