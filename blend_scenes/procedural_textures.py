"""Procedural, tileable images for the textured benchmark scenes (``build_scenes.py``).

numpy only, fixed seeds: rebuilding the scenes reproduces the same texels. Every function
returns float arrays in [0, 1] of shape (n, n, 3) (sRGB-encoded colour, stored as 8-bit
sRGB images) or (n, n) (data: heights, roughness), periodic in both directions so they tile
without seams. Normal maps are derived from heights by central differences
(:func:`normal_map`, tangent space, +Z up, OpenGL convention as Blender's Normal Map node).
"""
from __future__ import annotations

import numpy as np


def value_noise(n: int, cells: int, rng: np.random.Generator, octaves: int = 4) -> np.ndarray:
    """(n, n) periodic fractal value noise in [0, 1]: a random ``cells``² grid, smoothstep-
    interpolated with wrap-around, octaves of doubling frequency and halving amplitude."""
    out = np.zeros((n, n))
    amp, total = 1.0, 0.0
    for o in range(octaves):
        c = cells * 2 ** o
        grid = rng.random((c, c))
        x = np.arange(n) * c / n
        i0 = np.floor(x).astype(int)
        t = x - i0
        t = t * t * (3 - 2 * t)
        i0, i1 = i0 % c, (i0 + 1) % c
        rows = grid[i0] * (1 - t)[:, None] + grid[i1] * t[:, None]          # along y
        layer = rows[:, i0] * (1 - t)[None, :] + rows[:, i1] * t[None, :]    # along x
        out += amp * layer
        total += amp
        amp *= 0.5
    return out / total


def wood_planks(n: int, rng: np.random.Generator, planks: int = 4):
    """Planks along u: per-plank tint, grain streaks, dark seams. (colour, height, roughness)."""
    y, x = np.mgrid[0:n, 0:n] / n
    plank = np.floor(y * planks).astype(int)
    tint = rng.uniform(0.75, 1.15, planks)[plank]
    offset = rng.random(planks)[plank]
    grain = value_noise(n, 4, rng, 3)
    streak = 0.5 + 0.5 * np.sin(2 * np.pi * (12 * y + 3 * grain + 8 * offset + 2 * x))
    base = np.array([0.55, 0.36, 0.2]) * tint[..., None] * (0.8 + 0.25 * streak)[..., None]
    seam_dist = np.abs(((y * planks) % 1.0) - 0.5) * 2       # 1 at the seams
    seam = np.clip((seam_dist - 0.94) / 0.06, 0, 1)
    colour = base * (1 - 0.6 * seam)[..., None]
    height = 1 - seam + 0.05 * grain
    rough = 0.45 + 0.25 * grain + 0.2 * seam
    return np.clip(colour, 0, 1), np.clip(height, 0, 1), np.clip(rough, 0, 1)


def plaster(n: int, rng: np.random.Generator):
    """Off-white plaster: low-contrast blotches (colour) and fine relief (height)."""
    blot = value_noise(n, 4, rng, 5)
    fine = value_noise(n, 32, rng, 2)
    colour = np.array([0.82, 0.79, 0.72]) * (0.88 + 0.15 * blot)[..., None]
    return np.clip(colour, 0, 1), 0.6 * fine + 0.4 * blot


def fabric(n: int, rng: np.random.Generator, a=(0.25, 0.32, 0.45), b=(0.55, 0.58, 0.62)):
    """A woven fabric: two yarn colours in a twill pattern with slub noise; the second
    output is the weave's mix factor (data), used as a Mix Shader factor."""
    y, x = np.mgrid[0:n, 0:n]
    twill = (((x // 4) + (y // 4)) % 4 < 2).astype(float)
    slub = value_noise(n, 16, rng, 2)
    f = np.clip(0.8 * twill + 0.4 * (slub - 0.5), 0, 1)
    colour = np.array(a) * (1 - f[..., None]) + np.array(b) * f[..., None]
    return np.clip(colour * (0.9 + 0.2 * slub)[..., None], 0, 1), f


def rug(n: int, rng: np.random.Generator):
    """A bordered rug with a medallion: red field, cream border, blue ornament."""
    y, x = (np.mgrid[0:n, 0:n] + 0.5) / n
    r = np.hypot(x - 0.5, y - 0.5)
    edge = np.minimum(np.minimum(x, 1 - x), np.minimum(y, 1 - y))
    colour = np.ones((n, n, 3)) * [0.55, 0.12, 0.1]
    colour[(edge < 0.08)] = [0.85, 0.78, 0.6]
    colour[(edge > 0.1) & (edge < 0.12)] = [0.15, 0.2, 0.45]
    ring = np.abs(np.sin(2 * np.pi * 4 * r)) > 0.8
    colour[(r < 0.3) & ring] = [0.15, 0.2, 0.45]
    colour *= (0.85 + 0.3 * value_noise(n, 32, rng, 2))[..., None]
    return np.clip(colour, 0, 1)


def tiles(n: int, rng: np.random.Generator, count: int = 4):
    """Square ceramic tiles with grout lines: (colour, height)."""
    y, x = np.mgrid[0:n, 0:n] / n
    tx, ty = (x * count) % 1.0, (y * count) % 1.0
    grout = (np.minimum(np.minimum(tx, 1 - tx), np.minimum(ty, 1 - ty)) < 0.04).astype(float)
    idx = (np.floor(x * count) + count * np.floor(y * count)).astype(int)
    tint = rng.uniform(0.9, 1.05, count * count)[idx]
    colour = np.array([0.72, 0.7, 0.64]) * tint[..., None]
    colour = colour * (1 - grout[..., None]) + np.array([0.35, 0.33, 0.3]) * grout[..., None]
    height = 1 - grout + 0.03 * value_noise(n, 16, rng, 2)
    return np.clip(colour, 0, 1), np.clip(height, 0, 1)


def wallpaper(n: int, rng: np.random.Generator):
    """Vertical stripes (sage / cream) with a faint paper grain."""
    y, x = np.mgrid[0:n, 0:n] / n
    stripe = (np.floor(x * 8) % 2)[..., None]
    colour = np.array([0.55, 0.62, 0.5]) * stripe + np.array([0.86, 0.83, 0.74]) * (1 - stripe)
    return np.clip(colour * (0.93 + 0.1 * value_noise(n, 64, rng, 1))[..., None], 0, 1)


def normal_map(height: np.ndarray, strength: float) -> np.ndarray:
    """(n, n, 3) tangent-space normal map encoded as (N + 1)/2 from a periodic height field
    (units: height 1 = ``strength`` texels): N ∝ (−∂h/∂u, −∂h/∂v, 1)."""
    dx = (np.roll(height, -1, axis=1) - np.roll(height, 1, axis=1)) * 0.5 * strength
    dy = (np.roll(height, -1, axis=0) - np.roll(height, 1, axis=0)) * 0.5 * strength
    nrm = np.stack([-dx, -dy, np.ones_like(height)], axis=2)
    nrm /= np.linalg.norm(nrm, axis=2, keepdims=True)
    return nrm * 0.5 + 0.5
