"""Tracer: batched queries, embreex conventions and self-intersection offsets near and far."""
from __future__ import annotations

import numpy as np
import pytest

from ercuts_core.tracer import Tracer


def plane(center, size=1.0):
    c = np.asarray(center, float)
    v = np.array([[-1, 0, -1], [1, 0, -1], [1, 0, 1], [-1, 0, 1]], float) * size + c
    return v.astype(np.float32), np.array([[0, 2, 1], [0, 3, 2]], np.int32)


def test_intersect_hits_and_misses():
    tr = Tracer(*plane((0, 0, 0)))
    o = np.array([[0.2, 1, 0.3], [5, 1, 5]])
    d = np.array([[0, -1, 0], [0, -1, 0]], float)
    hit = tr.intersect(o, d)
    assert list(hit.valid) == [True, False]
    assert hit.t[0] == pytest.approx(1.0, abs=1e-6) and np.isinf(hit.t[1])


def test_occluded_convention():
    tr = Tracer(*plane((0, 0, 0)))
    o = np.array([[0, 1, 0], [0, 1, 0]], float)
    d = np.array([[0, -1, 0], [0, 1, 0]], float)
    assert list(tr.occluded(o, d, np.array([2.0, 2.0]))) == [True, False]
    assert not tr.occluded(o[:1], d[:1], np.array([0.5]))[0]  # segment ends before the plane


@pytest.mark.parametrize("scale,center", [(1.0, 0.0), (1.0, 1e4), (100.0, 1e4), (0.01, 10.0)])
def test_offsets_avoid_self_intersection_far_from_origin(scale, center):
    """Rays leaving a surface at 1e4 m never re-hit it, on either side and at grazing angles."""
    pos, tris = plane((center, center, center), size=scale)
    tr = Tracer(pos, tris)
    rng = np.random.default_rng(1)
    n = 20000
    p = np.c_[rng.uniform(-0.9, 0.9, n) * scale + center, np.full(n, center),
              rng.uniform(-0.9, 0.9, n) * scale + center]
    ng = np.tile([0.0, 1.0, 0.0], (n, 1))
    d = rng.normal(size=(n, 3))
    d[:, 1] = np.sign(d[:, 1]) * np.maximum(np.abs(d[:, 1]), 1e-3)  # down to grazing
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    o = tr.offset(p, ng, d)
    assert not tr.intersect(o, d).valid.any()
    # Visibility between pairs of points on the same plane is never blocked by the plane.
    q = np.roll(p, 1, axis=0)
    assert tr.visible(p, ng, q, ng).all()


def test_visibility_blocked_by_a_wall_far_from_origin():
    c = 1e4
    pos1, t1 = plane((c, c, c))
    wall = np.array([[c - 2, c + 0.5, c - 2], [c + 2, c + 0.5, c - 2], [c + 2, c + 0.5, c + 2],
                     [c - 2, c + 0.5, c + 2]], np.float32)
    tr = Tracer(np.vstack([pos1, wall]), np.vstack([t1, t1 + 4]))
    p = np.array([[c, c, c]])
    ng = np.array([[0.0, 1.0, 0.0]])
    assert not tr.visible(p, ng, p + [[0, 1.0, 0]], None)[0]
    assert tr.visible(p, ng, p + [[0, 0.4, 0]], None)[0]


def test_large_batches_are_split_across_threads_consistently():
    tr = Tracer(*plane((0, 0, 0)), threads=2)
    rng = np.random.default_rng(0)
    n = 100_000
    o = np.c_[rng.uniform(-2, 2, n), np.ones(n), rng.uniform(-2, 2, n)]
    d = np.tile([0.0, -1.0, 0.0], (n, 1))
    hit = tr.intersect(o, d)
    expect = (np.abs(o[:, 0]) < 1) & (np.abs(o[:, 2]) < 1)
    assert (hit.valid == expect).mean() > 0.9999
    assert tr.rays_traced == n


def test_a_shut_down_thread_pool_traces_in_the_calling_thread():
    """At interpreter exit Python shuts the pool before atexit handlers run; a render still in
    flight (a viewport thread when Blender quits) must finish its batch, not raise."""
    tr = Tracer(*plane((0, 0, 0)), threads=2)
    n = 100_000
    o = np.c_[np.linspace(-2, 2, n), np.ones(n), np.zeros(n)]
    d = np.tile([0.0, -1.0, 0.0], (n, 1))
    before = tr.intersect(o, d)
    tr._pool.shutdown()
    after = tr.intersect(o, d)
    np.testing.assert_array_equal(after.prim, before.prim)
    np.testing.assert_array_equal(tr.occluded(o, d, 2.0), before.valid)


def corner(center=0.0):
    """A concave corner: a floor (y = c, normal +y) and a wall (x = c, normal +x) sharing the
    edge x = y = c, z ∈ [c − 1, c + 1] (like a room's floor and wall, or the Cornell box's
    ceiling and side walls)."""
    c = center
    pos = np.array([[c, c, c - 1], [c + 2, c, c - 1], [c + 2, c, c + 1], [c, c, c + 1],      # floor
                    [c, c, c - 1], [c, c, c + 1], [c, c + 2, c + 1], [c, c + 2, c - 1]],     # wall
                   np.float32)
    tris = np.array([[0, 3, 2], [0, 2, 1], [4, 7, 6], [4, 6, 5]], np.int32)
    return pos, tris


@pytest.mark.parametrize("center", [0.0, 1.0, 100.0])
def test_points_on_a_shared_concave_edge_see_the_room(center):
    """A camera ray through a pixel centre that projects onto a room's corner hits the edge
    two surfaces share: the hit point (from barycentrics, like ``BuiltScene.surface``) is on
    both planes or a rounding error beyond one. Offset along its own normal only, it stayed
    on the other plane, and every shadow ray into the room was blocked at t = 0 (Cornell
    box: 29 black pixels along the ceiling corners). Such points must see the room, and
    rays spawned from them must leave into it."""
    c = center
    pos, tris = corner(c)
    tr = Tracer(pos, tris, threads=1)
    rng = np.random.default_rng(3)
    n = 4000
    eye = np.c_[rng.uniform(0.3, 1.9, n) + c, rng.uniform(0.3, 1.9, n) + c, rng.uniform(-1, 1, n) + c]
    edge = np.c_[np.full(n, c), np.full(n, c), rng.uniform(-0.9, 0.9, n) + c]
    view = (edge - eye) / np.linalg.norm(edge - eye, axis=1, keepdims=True)
    hit = tr.intersect(eye, view)
    assert hit.valid.all()
    v = pos[tris[hit.prim]].astype(np.float64)                                    # (n, 3, 3)
    p = (1 - hit.u - hit.v)[:, None] * v[:, 0] + hit.u[:, None] * v[:, 1] + hit.v[:, None] * v[:, 2]
    ng = np.where((hit.prim < 2)[:, None], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0])
    assert np.abs(p - edge).max() < 1e-6 * max(1.0, c) and (hit.prim < 2).any() and (hit.prim >= 2).any()
    q = np.c_[rng.uniform(0.05, 1.9, n) + c, rng.uniform(0.05, 1.9, n) + c, rng.uniform(-1, 1, n) + c]
    assert tr.visible(p, ng, q, None).all()
    d = (q - p) / np.linalg.norm(q - p, axis=1, keepdims=True)
    assert not tr.intersect(tr.offset(p, ng, d), d).valid.any()  # nothing but open space


@pytest.mark.parametrize("length", [1.0, 1e3, 1e5])
def test_long_shadow_rays_keep_thin_blockers_near_their_ends(length):
    """The offset along the ray is eps along a *unit* direction, whatever the segment's
    length: a blocker 1 mm above a 2 m floor still blocks a shadow ray to a point
    ``length`` away (an offset of eps·|p1 − p0| stepped over it from 1 km on). From the far
    end the segment stops 1e-6 of its length short, so that direction is checked at 10 m."""
    ground, tris = plane((0, 0, 0))
    blocker = np.array([[-1, 1e-3, -1], [1, 1e-3, -1], [1, 1e-3, 1], [-1, 1e-3, 1]], np.float32) * [0.01, 1, 0.01]
    tr = Tracer(np.vstack([ground, blocker]), np.vstack([tris, tris + 4]), threads=1)
    p0 = np.array([[0.0, 0.0, 0.0]])
    up = np.array([[0.0, 1.0, 0.0]])
    far = p0 + [[0.0, length, 0.0]]
    assert not tr.visible(p0, up, far, None)[0]
    assert not tr.visible(p0 + [[0.0, 10.0, 0.0]], None, p0, up)[0]
    assert tr.visible(p0 + [[0.05, 0, 0]], up, far + [[0.05, 0, 0]], None)[0]   # beside it: free


def test_unused_nonfinite_vertex_leaves_offsets_finite():
    """validate drops the triangles of a NaN/Inf vertex but keeps the vertex: the offsets'
    scene size comes from the vertices triangles use (an infinite one made every offset
    infinite and every ray from a surface NaN)."""
    pos, tris = plane((0, 0, 0))
    tr = Tracer(np.vstack([pos, [[-np.inf, 0, 0], [np.nan, 1, 2]]]).astype(np.float32), tris, threads=1)
    assert tr.diagonal == pytest.approx(np.sqrt(8.0))
    p = np.array([[0.2, 0.0, 0.3]])
    o = tr.offset(p, np.array([[0.0, 1.0, 0.0]]), np.array([[0.0, 1.0, 0.0]]))
    assert np.isfinite(o).all() and 0 < o[0, 1] < 1e-4


def test_origins_beyond_float32_range_miss_quietly():
    """A scene spanning ±3e38 m puts e.g. a sun's emission disk beyond float32's range:
    such rays miss, without an overflow warning (warnings are errors in the tests)."""
    tr = Tracer(*plane((0, 0, 0)), threads=1)
    o = np.array([[0.0, 4e38, 0.0], [0.0, 1.0, 0.0]])
    d = np.array([[0.0, -1.0, 0.0], [0.0, -1.0, 0.0]])
    assert list(tr.intersect(o, d).valid) == [False, True]
    assert list(tr.occluded(o, d, np.array([5e38, 2.0]))) == [False, True]
