"""Point and spot lights with a radius r > 0, as Cycles renders them.

Cycles (``kernel/light/point.h``, ``spot.h``, ``scene/light.cpp``; Blender 3.4 and 5.0) gives
such a light the radiance L = I/(π·r²) (I its intensity, Blender's P/(4π)) over one of two
shapes, chosen by ``is_sphere`` = not *Soft Falloff*:

* **sphere** (Blender ≥ 4.0 with Soft Falloff off): a Lambertian sphere of radius r. Next-event
  estimation from a receiver x outside it samples the visible cap uniformly in solid angle,
  Ω = 2π(1 − cosα), sinα = r/|x − c|; from inside, every direction sees L (no spot factor)
  and is sampled uniformly on the sphere of directions (Cycles samples the cosine hemisphere
  of the shading normal there; this interface has no normal — same integrand, other pdf).
* **disk** (Soft Falloff on — Blender's default — and every Blender 3.x): a disk of radius r
  centred on the light *facing the receiver*, sampled uniformly in area (pdf_w = t²/(πr²·cos)).

The spot factor is evaluated along the ray from the light point toward the receiver.

**Emission** (light tracing, BDPT light subpaths). Both shapes emit the lines that pass
within r of the centre c: a direction ω from the light's direction density p(ω) (uniform in
the spot cone, or on the sphere), then the line's closest point to c uniform on the disk of
radius r through c perpendicular to ω, i.e. the density p(ω)/(π·r²) in the line measure
dA⊥·dω. A line at distance b from c carries L·spot(ω):

* sphere: from its exit point o = c + b⃗ + ω·√(r² − b²), the surface point facing ω;
* disk: from its closest point o = c + b⃗, and only to receivers x whose facing disk it
  crosses: b ≤ ρ(d) = r·d/√(d² + r²), d = |x − c| (:func:`reaches`) — the lines through x
  within the disk's cone (tan β = r/d). Light tracing is then exact except for occluders
  within r of the centre (the shadow ray of next-event estimation starts on the facing disk).

So a light path is a (line, receiver) pair whichever strategy made it, and the densities
the MIS weights need are those of the emission: ``pdf_pos`` = 1/(π·r²) for every line and
``pdf_dir`` = p(ω) per unit dω of the projected start point. At a next-event sample p the
conversion BDPT applies uses |x − p|², so :func:`line_start` gives the emission's start o and
the caller scales pdf_dir by |x − p|²/|x − o|² (1 for the sphere, where o = p).

All arrays are float64: points (N, 3) [m], radii (N,) [m], densities per sr or per m².
"""
from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from .sampling import (coordinate_system, one_minus_cos_from_sin2, sample_uniform_cone_omc,
                       sample_uniform_disk_concentric, sample_uniform_sphere, to_world,
                       uniform_cone_pdf_omc)
from .vecmath import dot, normalize

_INV_4PI = 0.25 / np.pi


def sample_from_receiver(c: NDArray, r: NDArray, sphere: NDArray, x: NDArray,
                         u: NDArray) -> tuple[NDArray, NDArray, NDArray]:
    """Next-event sample of the light point seen from receivers x (Cycles ``point_light_sample``).

    Args:
        c: (N, 3) light centres; r: (N,) radii > 0; sphere: (N,) bool shape; x: (N, 3)
        receivers; u: (N, 2) uniforms.
    Returns:
        p (N, 3) the point on the sphere or facing disk, pdf_w (N,) its solid-angle density
        at x, inside (N,) x lies inside a sphere light (no spot factor, no emission line).
    """
    v, d = normalize(x - c)               # v: centre → receiver
    r2, d2 = r * r, d * d
    inside = sphere & (d2 <= r2)
    p = np.empty_like(x)
    pdf = np.empty(len(x))
    cap = sphere & ~inside
    if cap.any():
        omc = one_minus_cos_from_sin2(r2[cap] / d2[cap])
        t_, b_ = coordinate_system(-v[cap])
        w = to_world(sample_uniform_cone_omc(u[cap], omc), t_, b_, -v[cap])
        p[cap] = _on_sphere(c[cap], r[cap], x[cap], w, d[cap], -1.0)
        pdf[cap] = uniform_cone_pdf_omc(omc)
    if inside.any():
        w = sample_uniform_sphere(u[inside])
        p[inside] = _on_sphere(c[inside], r[inside], x[inside], w, d[inside], 1.0)
        pdf[inside] = _INV_4PI
    disk = ~sphere
    if disk.any():
        p[disk] = _disk_point(c[disk], r[disk], v[disk], u[disk])
        w, t = normalize(p[disk] - x[disk])
        cos_l = np.maximum(-dot(v[disk], w), 1e-300)
        pdf[disk] = t * t / (np.pi * r2[disk] * cos_l)
    return p, pdf, inside


def _on_sphere(c, r, x, w, d, sign: float) -> NDArray:
    """The point of the sphere (c, r) hit from x along unit w: the near hit (sign −1, x
    outside) or the hit from inside (+1), law of cosines as Cycles, then put exactly on the
    sphere (``ls->P = Ng·r + co``)."""
    cos_t = dot(w, c - x) / np.maximum(d, 1e-300)
    disc = np.maximum(r * r - d * d * (1.0 - cos_t * cos_t), 0.0)
    t = d * cos_t + sign * np.sqrt(disc)
    n, _ = normalize(x + w * t[:, None] - c)
    return c + n * r[:, None]


def _disk_point(c, r, n, u) -> NDArray:
    """(N, 3) uniform points of the disks of radii r centred at c with unit normals n."""
    t_, b_ = coordinate_system(n)
    q = sample_uniform_disk_concentric(u) * r[:, None]
    return c + q[:, :1] * t_ + q[:, 1:] * b_


def pdf_from_receiver(c: NDArray, r: NDArray, sphere: NDArray, x: NDArray,
                      p: NDArray) -> NDArray:
    """(N,) solid-angle density with which :func:`sample_from_receiver` from x picks the
    direction toward p (a point it could return; 0 for a point on the sphere's far side)."""
    v, d = normalize(x - c)
    r2, d2 = r * r, d * d
    w, t = normalize(p - x)
    out = np.zeros(len(x))
    cap = sphere & (d2 > r2)
    near = dot(p - c, v) >= r2 / np.maximum(d, 1e-300) * (1.0 - 1e-9)   # the visible cap
    out[cap & near] = uniform_cone_pdf_omc(one_minus_cos_from_sin2(r2 / d2))[cap & near]
    out[sphere & (d2 <= r2)] = _INV_4PI
    disk = ~sphere
    cos_l = np.maximum(-dot(v, w), 1e-300)
    out[disk] = (t * t / (np.pi * r2 * cos_l))[disk]
    return out


def emit_points(c: NDArray, r: NDArray, sphere: NDArray, w: NDArray, u: NDArray) -> NDArray:
    """(N, 3) start points of emitted lines with unit directions w (module docstring):
    closest point to c uniform on the disk ⊥ w of radius r; the sphere's exit point from there."""
    q = _disk_point(c, r, w, u)
    out = q.copy()
    if sphere.any():
        b2 = dot(q - c, q - c)
        out[sphere] = q[sphere] + w[sphere] * np.sqrt(np.maximum(r * r - b2, 0.0))[sphere, None]
    return out


def line_start(c: NDArray, sphere: NDArray, p: NDArray, w: NDArray) -> NDArray:
    """(N, 3) where the emission starts the line through light point p with unit direction w:
    p itself on a sphere (a next-event point is the exit point toward the receiver), the
    line's closest point to c for a disk."""
    closest = p + dot(c - p, w)[:, None] * w
    return np.where(sphere[:, None], p, closest)


def reaches(c: NDArray, r: NDArray, sphere: NDArray, o: NDArray, x: NDArray) -> NDArray:
    """(N,) bool: the line emitted from o lights the receiver x further along it — always on
    a sphere; on a disk when its distance b = |o − c| to the centre is at most
    ρ(d) = r·d/√(d² + r²), d = |x − c| (the receiver's facing disk covers the line)."""
    b2 = dot(o - c, o - c)
    d2 = dot(x - c, x - c)
    rho2 = r * r * d2 / (d2 + r * r)
    return sphere | (b2 <= rho2 * (1.0 + 1e-12))
