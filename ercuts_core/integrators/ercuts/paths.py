"""Eye-first light paths as padded arrays, and their measurement contribution.

A batch of C paths ``X = x0 x1 … x_k`` (x0 the camera, x_k on a light) is stored as padded
(C, K, …) arrays with K = max_depth + 2 vertex slots. The chains of the ER step mutate these.

State space and measure. A path is parameterised by the raster position ``u`` of x1
(pixel units) and the vertices x2 … x_k: surface vertices in the area measure, a point
light by counting, a sun by counting and an environment direction by solid angle. In this
measure the camera factor W_e·G(x0,x1)/p(x1|u) is 1, so the contribution is the path
tracer's integrand [Veach 1997 eq. 8.7 with the pixel filter absorbed]::

    f(X) = Π_{i=1}^{k-1} f_r(x_i) · Π_{i=1}^{k-2} G(x_i, x_{i+1}) · T_k
    G(x_i, x_j) = |n_s(x_i)·ω| · |n_g(x_j)·ω| / d²        (visibility tested separately)
    T_k = |n_s(x_{k-1})·ω| · { |n_g·ω|/d² · L_e   area / emissive triangle
                              1/d² · I(ω)          point / spot
                              E                    sun
                              L_env                environment }

Only paths whose x2 is a surface point can become VPLs (paper §3.3); :func:`is_target`
marks them, and the chains' target function is f·[is_target].

Soft lights: a point/spot light of radius r > 0 is stored as its centre and evaluated as a
point (:meth:`~ercuts_core.lights.LightSet.chain_vertex`: only the chains' target in the
light's penumbra is approximated); a sun's direction is the one sampled in its cone (uniform,
so the counting measure stays exact); spread area lights emit ``LightSet.area_radiance``.
With depth of field x0 is the path's lens point (part of the state, uniform on the aperture,
so the camera factor stays 1).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ...arrays import take_rows
from ...lights import AREA, ENV, POINT, SUN, TRI
from ...scene import BuiltScene
from ...vecmath import dot


@dataclass
class PathBatch:
    """C eye-first paths (see module docstring).

    Attributes:
        raster: (C, 2) full-frame raster position of x1.
        p: (C, K, 3) vertex positions; slot k holds the light point (POINT: its position;
            SUN/ENV: the unit direction from x_{k-1} toward the light).
        ng: (C, K, 3) unit geometric normals (zero for x0 and point/infinite lights).
        ns: (C, K, 3) unit shading normals.
        mat: (C, K) material rows of surface vertices.
        k: (C,) index of the light vertex (= number of edges).
        light: (C,) global light index of x_k.
    """

    raster: NDArray
    p: NDArray
    ng: NDArray
    ns: NDArray
    mat: NDArray
    k: NDArray
    light: NDArray

    @staticmethod
    def empty(n: int, slots: int) -> "PathBatch":
        return PathBatch(np.zeros((n, 2)), np.zeros((n, slots, 3)), np.zeros((n, slots, 3)),
                         np.zeros((n, slots, 3)), np.zeros((n, slots), np.int64),
                         np.zeros(n, np.int64), np.zeros(n, np.int64))

    def __len__(self) -> int:
        return len(self.k)

    @property
    def slots(self) -> int:
        return self.p.shape[1]

    def take(self, idx) -> "PathBatch":
        return PathBatch(*(take_rows(a, idx) for a in (self.raster, self.p, self.ng, self.ns, self.mat,
                                                       self.k, self.light)))

    def put(self, idx, other: "PathBatch") -> None:
        """Overwrite paths ``idx`` with ``other`` (in place)."""
        self.raster[idx] = other.raster
        self.p[idx] = other.p
        self.ng[idx] = other.ng
        self.ns[idx] = other.ns
        self.mat[idx] = other.mat
        self.k[idx] = other.k
        self.light[idx] = other.light

    def copy(self) -> "PathBatch":
        """A deep copy (``take`` with a slice would return views)."""
        return PathBatch(*(getattr(self, f).copy() for f in
                           ("raster", "p", "ng", "ns", "mat", "k", "light")))

    @staticmethod
    def concat(parts: list["PathBatch"]) -> "PathBatch":
        return PathBatch(*(np.concatenate([getattr(q, f) for q in parts]) for f in
                           ("raster", "p", "ng", "ns", "mat", "k", "light")))

    def vertex(self, i: NDArray | int) -> tuple[NDArray, NDArray, NDArray, NDArray]:
        """Position, ng, ns, mat of vertex ``i`` (scalar or (C,)) of every path."""
        rows = np.arange(len(self))
        return tuple(slot_rows(a, rows, i) for a in (self.p, self.ng, self.ns, self.mat))


def slot_rows(a: NDArray, rows: NDArray, i) -> NDArray:
    """``a[rows, i]`` for a (C, K, ...) per-path slot array, i scalar or per row (one flat
    ``np.take``, ~3× faster than the 2-D fancy index)."""
    C, K = a.shape[:2]
    return a.reshape((C * K,) + a.shape[2:]).take(rows * K + i, axis=0)


def light_kind(scene: BuiltScene, paths: PathBatch) -> NDArray:
    """(C,) kind of each path's light vertex."""
    return scene.lights.kind[paths.light]


def is_target(scene: BuiltScene, paths: PathBatch, direct: bool = True) -> NDArray:
    """(C,) True where x2 exists and is a surface point (a VPL can sit there); with
    ``direct=False`` only where x2 also scatters (k ≥ 3: indirect light, the chains' class
    when direct light is rendered by next-event estimation, ``direct_light='NEE'``)."""
    if not direct:
        return paths.k >= 3
    kind = light_kind(scene, paths)
    surface_light = (kind == AREA) | (kind == TRI)
    return (paths.k >= 3) | ((paths.k == 2) & surface_light)


def x1_clear(scene: BuiltScene, paths: PathBatch, vertex: int = 1) -> NDArray:
    """(C,) x1 (or x_``vertex``) lies on a mirror or glass (``Bsdf.is_specular_or_glass``):
    with the gather following the camera through those, such paths are not the chains' (the
    direct-light passes and the gather behind the surface render them; no VPL sits on one)."""
    if not scene.has_specular_or_glass or len(paths) == 0:
        return np.zeros(len(paths), bool)
    p, ng, ns, mat = paths.vertex(vertex)
    return scene.bsdf(mat, ns, ng, p).is_specular_or_glass


def x1_or_x2_clear(scene: BuiltScene, paths: PathBatch) -> NDArray:
    """(C,) x1 or a surface x2 lies on a mirror or glass (:func:`x1_clear`)."""
    out = x1_clear(scene, paths)
    x2 = np.flatnonzero(~out & (paths.k >= 3))          # x2 scatters (else it is the light)
    out[x2] = x1_clear(scene, paths.take(x2), 2)
    return out


def contribution(scene: BuiltScene, paths: PathBatch, infinite_dir: NDArray | None = None,
                 with_x2_light: bool = False) -> tuple[NDArray, NDArray] | NDArray:
    """(C, 3) measurement contribution f(X) (module docstring), visibility not included.

    Args:
        with_x2_light: also return (C, 3) the light leaving x2 toward x1 in the same
            units (f / (f_r(x1)·G(x1,x2))), the colour of the VPL at x2.
    """
    lights = scene.lights
    C, K = len(paths), paths.slots
    rows = np.arange(C)
    kind = lights.kind[paths.light]
    infinite = (kind == SUN) | (kind == ENV)
    f = np.ones((C, 3))
    head = np.ones((C, 3))            # f_r(x1)·G(x1,x2): divided out for the x2 light
    for i in range(1, K - 1):
        act = i < paths.k
        if not act.any():
            break
        r = rows[act]
        xi, ngi, nsi, mi = (slot_rows(a, r, i) for a in (paths.p, paths.ng, paths.ns, paths.mat))
        wo = slot_rows(paths.p, r, i - 1) - xi
        wo /= np.maximum(np.sqrt(dot(wo, wo)), 1e-300)[:, None]
        last_edge = (i + 1) == paths.k[r]
        nxt = slot_rows(paths.p, r, i + 1)
        inf_edge = last_edge & infinite[r]
        d = np.where(inf_edge[:, None], nxt, nxt - xi)
        dist = np.sqrt(dot(d, d))
        wi = d / np.maximum(dist, 1e-300)[:, None]
        bsdf = scene.bsdf(mi, nsi, ngi, xi)
        fr = bsdf.eval(wo, wi) * np.abs(dot(nsi, wi))[:, None]
        # Conversion at the next vertex: area (surfaces), 1/d² (point), 1 (infinite).
        k_next = kind[r]
        surf_next = ~last_edge | (k_next == AREA) | (k_next == TRI)
        conv = np.where(surf_next, np.abs(dot(slot_rows(paths.ng, r, i + 1), wi)) / np.maximum(dist * dist, 1e-300),
                        np.where(inf_edge, 1.0, 1.0 / np.maximum(dist * dist, 1e-300)))
        term = fr * conv[:, None]
        f[r] *= term
        if i == 1:
            head[r] = term
        # Emission of the light vertex toward x_i.
        if last_edge.any():
            e = r[last_edge]
            f[e] *= _emitted(scene, paths, e, -wi[last_edge])
    f[paths.k < 2] = 0.0
    if with_x2_light:
        safe = np.where(head > 0, head, 1.0)
        return f, np.where(head > 0, f / safe, 0.0)
    return f


def _emitted(scene: BuiltScene, paths: PathBatch, rows: NDArray, w_out: NDArray) -> NDArray:
    """(n, 3) radiance (or intensity / irradiance) leaving the light vertex along ``w_out``."""
    lights = scene.lights
    light = paths.light[rows]
    kind, loc = lights.kind[light], lights.local[light]
    out = np.zeros((len(rows), 3))
    m = kind == AREA
    if m.any():
        out[m] = lights.area_radiance(loc[m], w_out[m])
    m = kind == TRI
    if m.any():
        out[m] = lights.tri_radiance_at(loc[m], slot_rows(paths.p, rows[m], paths.k[rows[m]]))
    m = kind == POINT
    if m.any():
        out[m] = lights.pt_I[loc[m]] * lights.spot_factor(loc[m], w_out[m])[:, None]
    m = kind == SUN
    if m.any():
        out[m] = lights.sun_E[loc[m]]
    m = kind == ENV
    if m.any():
        out[m] = lights.env_radiance(-w_out[m])     # radiance travelling along w_out
    return out


def edge_visible(scene: BuiltScene, paths: PathBatch, i: NDArray) -> NDArray:
    """(C,) visibility of edge x_i → x_{i+1} (i ≥ 1) for every path."""
    C = len(paths)
    rows = np.arange(C)
    kind = scene.lights.kind[paths.light]
    a, nga = slot_rows(paths.p, rows, i), slot_rows(paths.ng, rows, i)
    j = i + 1
    b, ngb = slot_rows(paths.p, rows, j), slot_rows(paths.ng, rows, j)
    last = j == paths.k
    infinite = last & ((kind == SUN) | (kind == ENV))
    b = np.where(infinite[:, None], a + b * 4.0 * scene.scene_radius, b)
    point_end = last & ((kind == POINT) | infinite)
    vis = np.ones(C, bool)
    s = ~point_end
    if s.any():
        vis[s] = scene.tracer.visible(a[s], nga[s], b[s], ngb[s])
    if point_end.any():
        vis[point_end] = scene.tracer.visible(a[point_end], nga[point_end], b[point_end], None)
    return vis


