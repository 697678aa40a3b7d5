"""Image textures: the scene's texture table and vectorized lookups with Blender's conventions.

Conventions (Blender / Cycles, ``intern/cycles/kernel/device/cpu/image.h``):

* An image is (H, W, 4) float32 linear RGBA with *straight* alpha; row 0 is the image's
  bottom (Blender's pixel order), so texel (i, j) covers u ∈ [j/W, (j+1)/W],
  v ∈ [i/H, (i+1)/H] and its centre is at ((j + 0.5)/W, (i + 0.5)/H).
* An image flagged ``srgb`` holds sRGB-*encoded* RGB instead (alpha linear): lookups
  interpolate the encoded values and decode after (:func:`srgb_to_linear`), as Cycles does
  for 8-bit sRGB images (``compress_as_srgb``, kernel/svm/image.h); Closest lookups are the
  same either way, Linear ones differ where neighbouring texels differ (between a white and
  a blue texel the midpoint is 29 % darker than interpolating linear values).
* ``Closest``: the texel containing (u, v): j = floor(u·W).
* ``Linear``: bilinear between the four texels whose centres surround (u, v):
  x = u·W − 0.5, j0 = floor(x), weight of j0 + 1 is x − j0 (Cycles' ``frac``).
* ``Cubic`` (and ``Smart``) fall back to ``Linear`` here (not Cycles' B-spline): a
  documented gap, visible only on magnified textures.
* Extension: ``REPEAT`` wraps texel indices modulo the size; ``EXTEND`` clamps them to the
  edge; ``CLIP`` returns transparent black (0, 0, 0, 0) for (u, v) outside [0, 1]² and,
  inside, treats texels beyond the edge as transparent black (bilinear fades to 0 over
  the border half-texel as in Cycles); ``MIRROR`` reflects the index at every edge
  (period 2W: j → j mod 2W, then 2W − 1 − j for the second half).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

F32 = NDArray[np.float32]

INTERPOLATIONS = ("Closest", "Linear", "Cubic", "Smart")
EXTENSIONS = ("REPEAT", "EXTEND", "CLIP", "MIRROR")

#: The colour Cycles renders for a missing or unreadable image (linear RGBA).
MISSING_COLOR = (1.0, 0.0, 1.0, 1.0)


def missing_image() -> F32:
    """The 1×1 magenta image used for missing / zero-size images (Cycles' convention)."""
    return np.array(MISSING_COLOR, np.float32).reshape(1, 1, 4)


@dataclass(frozen=True)
class TextureTable:
    """Every image of the scene, once each.

    Attributes:
        names: image names, for messages.
        images: (H, W, 4) float32 C-contiguous linear straight-alpha RGBA per image,
            row 0 at the bottom. ``MaterialTable.programs`` refer to them by row.
        srgb: per image, True where RGB is sRGB-encoded (module docstring); default
            (``()``, or shorter than ``images``): False.
    """

    names: tuple[str, ...] = ()
    images: tuple[np.ndarray, ...] = field(default_factory=tuple)
    srgb: tuple[bool, ...] = ()

    def __post_init__(self):
        object.__setattr__(self, "names", tuple(str(n) for n in self.names))
        object.__setattr__(self, "images", tuple(np.ascontiguousarray(np.asarray(im, np.float32))
                                                 for im in self.images))
        flags = tuple(bool(f) for f in self.srgb)[:len(self.images)]
        object.__setattr__(self, "srgb", flags + (False,) * (len(self.images) - len(flags)))

    def __len__(self) -> int:
        return len(self.images)

    def linear(self, row: int) -> F32:
        """(H, W, 4) float32 linear RGBA of image ``row`` (decoded if it is sRGB-encoded)."""
        image = self.images[row]
        if not self.srgb[row]:
            return image
        out = image.copy()
        out[..., :3] = srgb_to_linear(image[..., :3])
        return out

    @property
    def nbytes(self) -> int:
        """Memory held by the images [bytes] (for the memory plan)."""
        return int(sum(im.nbytes for im in self.images))


def srgb_to_linear(c: NDArray) -> NDArray:
    """The piecewise sRGB EOTF (IEC 61966-2-1) as Cycles' ``color_srgb_to_linear``
    (util/color.h): c/12.92 below 0.04045 (0 for c < 0), ((c + 0.055)/1.055)^2.4 above;
    float64 (float32 in: float32 out)."""
    c = np.asarray(c)
    lo = np.where(c < 0.0, 0.0, c / 12.92)
    hi = ((np.maximum(c, 0.04045) + 0.055) / 1.055) ** 2.4
    return np.where(c < 0.04045, lo, hi).astype(np.result_type(c.dtype, np.float32))


# ---------------------------------------------------------------------------------------
# Lookup
# ---------------------------------------------------------------------------------------


def _wrap(idx: NDArray, size: int, extension: str) -> tuple[NDArray, NDArray]:
    """Texel indices (any int array) → (in-range indices, inside mask) for one axis.

    ``inside`` is False only for CLIP indices beyond the edge (they read transparent black).
    """
    if extension == "REPEAT":
        return np.mod(idx, size), np.ones(idx.shape, bool)
    if extension == "MIRROR":
        m = np.mod(idx, 2 * size)
        return np.where(m >= size, 2 * size - 1 - m, m), np.ones(idx.shape, bool)
    inside = (idx >= 0) & (idx < size)
    clamped = np.clip(idx, 0, size - 1)
    if extension == "CLIP":
        return clamped, inside
    return clamped, np.ones(idx.shape, bool)           # EXTEND


def _fetch(image: F32, i: NDArray, j: NDArray, extension: str) -> NDArray:
    """Texels (N, 4) float64 at integer rows i, columns j (N,), wrapped per ``extension``."""
    h, w = image.shape[:2]
    ii, in_i = _wrap(i, h, extension)
    jj, in_j = _wrap(j, w, extension)
    return _gather(image, ii, jj, in_i & in_j if extension == "CLIP" else None)


def _gather(image: F32, ii: NDArray, jj: NDArray, inside: NDArray | None) -> NDArray:
    """Texels at in-range (ii, jj) as (N, 4) float64 (one flat ``take``); zero where not ``inside``."""
    w = image.shape[1]
    out = np.take(image.reshape(-1, 4), ii * w + jj, axis=0).astype(np.float64)
    if inside is not None:
        out[~inside] = 0.0
    return out


def lookup(image: F32, uv: NDArray, interpolation: str = "Linear",
           extension: str = "REPEAT") -> NDArray:
    """Sample ``image`` at texture coordinates ``uv``.

    Args:
        image: (H, W, 4) float32 (row 0 at the bottom).
        uv: (N, 2) texture coordinates (u right, v up; [0, 1]² covers the image once).
        interpolation: 'Closest', 'Linear', 'Cubic' or 'Smart' (the last two as 'Linear').
        extension: 'REPEAT', 'EXTEND', 'CLIP' or 'MIRROR' (unknown values act as REPEAT).
    Returns:
        (N, 4) float64 RGBA. Non-finite uv read texel (0, 0) (Cycles would read garbage).
    """
    uv = np.asarray(uv, np.float64).reshape(-1, 2)
    uv = np.where(np.isfinite(uv), uv, 0.0)
    h, w = image.shape[:2]
    extension = extension if extension in EXTENSIONS else "REPEAT"
    # Coordinates so large they would overflow the int conversion: wrap them first.
    uv = np.clip(uv, -1e9, 1e9)
    x, y = uv[:, 0] * w, uv[:, 1] * h
    if interpolation == "Closest":
        out = _fetch(image, np.floor(y).astype(np.int64), np.floor(x).astype(np.int64), extension)
    else:
        x, y = x - 0.5, y - 0.5
        x0, y0 = np.floor(x), np.floor(y)
        fx, fy = (x - x0)[:, None], (y - y0)[:, None]
        j0, i0 = x0.astype(np.int64), y0.astype(np.int64)
        # Wrap each of the two rows and two columns once, then gather the four texels
        (r0, in_r0), (r1, in_r1) = _wrap(i0, h, extension), _wrap(i0 + 1, h, extension)
        (c0, in_c0), (c1, in_c1) = _wrap(j0, w, extension), _wrap(j0 + 1, w, extension)
        clip = extension == "CLIP"
        out = ((1 - fy) * ((1 - fx) * _gather(image, r0, c0, in_r0 & in_c0 if clip else None)
                           + fx * _gather(image, r0, c1, in_r0 & in_c1 if clip else None))
               + fy * ((1 - fx) * _gather(image, r1, c0, in_r1 & in_c0 if clip else None)
                       + fx * _gather(image, r1, c1, in_r1 & in_c1 if clip else None)))
    if extension == "CLIP":
        outside = ((uv < 0.0) | (uv > 1.0)).any(axis=1)
        out[outside] = 0.0
    return out
