"""Blender images → rows of ``ercuts_core.shading.textures.TextureTable``.

Each Blender image is read once (``image.pixels.foreach_get``, no per-pixel Python) into a
float32 (H, W, 4) array: linear RGB, *straight* alpha, row 0 = the image's bottom row
(Blender's order, kept as is).

Colour space (what ``image.pixels`` returns, and what Cycles does with it):

* byte images come back un-linearised (the file's 8-bit values / 255): with the colour
  space 'sRGB' the exact piecewise sRGB EOTF is applied to RGB (never to alpha); with a data
  space ('Non-Color', 'Raw': ``colorspace_settings.is_data``) or a linear one ('Linear',
  'Linear Rec.709', …) they are used untouched; any other space (Filmic, ACES, XYZ, …) is
  used untouched with a note.
* float images (EXR, HDR, float generated images) are already scene-linear: untouched.

Alpha (Blender's ``alpha_mode``, as Cycles reads it):

* STRAIGHT (default): byte pixels are straight alpha: used as they are. Float buffers are
  stored premultiplied by Blender (ImBuf's convention), so they are un-premultiplied.
* PREMUL: un-premultiplied (RGB / alpha where alpha > 0) before linearisation.
* CHANNEL_PACKED: RGB and alpha are independent data: untouched.
* NONE: alpha ignored: set to 1.

Cycles' Image Texture node outputs a premultiplied colour unless its Alpha output is
linked (for non-data, non-channel-packed images); :attr:`TextureInfo.associates` tells the
shader compiler when that matters (some alpha below 1), it then multiplies Color by Alpha.

A missing or unloadable image (no file, zero size, no pixels) becomes a 1×1 magenta texture
(Cycles' missing-texture colour, RGBA (1, 0, 1, 1)) with one warning naming image and
material; NaN/Inf pixels are replaced by 0 with a warning.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

MAGENTA = np.array([[[1.0, 0.0, 1.0, 1.0]]], np.float32)


def srgb_to_linear(c: np.ndarray) -> np.ndarray:
    """The exact piecewise sRGB EOTF (IEC 61966-2-1), float32 in, float32 out."""
    c = np.asarray(c, np.float32)
    lo = c / np.float32(12.92)
    hi = ((np.maximum(c, 0.04045) + np.float32(0.055)) / np.float32(1.055)) ** np.float32(2.4)
    return np.where(c <= 0.04045, lo, hi).astype(np.float32)


@dataclass
class TextureInfo:
    """What the shader compiler needs to know about a texture row."""

    mean_color: tuple
    mean_alpha: float
    associates: bool


def _is_linear_space(name: str) -> bool:
    n = name.lower()
    return n.startswith("linear") or n in {"scene_linear", "scene linear"}


def read_image(image) -> tuple[np.ndarray | None, list[str]]:
    """(H, W, 4) float32 linear straight-alpha pixels of ``image``, or None if unloadable."""
    notes: list[str] = []
    try:
        w, h = (int(x) for x in image.size)
        if w <= 0 or h <= 0:
            return None, notes
        n = len(image.pixels)
        if n == 0 or n % (w * h):
            return None, notes
        channels = n // (w * h)
        buf = np.empty(n, np.float32)
        image.pixels.foreach_get(buf)
    except (RuntimeError, ReferenceError, ValueError, OSError):
        return None, notes
    px = buf.reshape(h, w, channels)
    if channels == 4:
        rgba = px.copy()
    else:
        rgba = np.ones((h, w, 4), np.float32)
        if channels == 1:
            rgba[..., :3] = px[..., :1]
        elif channels == 2:
            rgba[..., :3] = px[..., :1]
            rgba[..., 3] = px[..., 1]
        else:
            rgba[..., :3] = px[..., :3]
    if not np.isfinite(rgba).all():
        notes.append("non-finite pixels replaced by 0")
        rgba = np.nan_to_num(rgba, nan=0.0, posinf=0.0, neginf=0.0)
    mode = getattr(image, "alpha_mode", "STRAIGHT")
    is_float = bool(getattr(image, "is_float", False))
    if mode == "NONE":
        rgba[..., 3] = 1.0
    elif mode == "PREMUL" or (is_float and mode == "STRAIGHT"):
        a = rgba[..., 3:4]
        with np.errstate(divide="ignore", invalid="ignore"):  # alpha 0: colour kept as stored
            rgba[..., :3] = np.where(a > 0, rgba[..., :3] / np.where(a > 0, a, 1), rgba[..., :3])
    settings = image.colorspace_settings
    space = settings.name
    if not is_float:
        if space == "sRGB":
            rgba[..., :3] = srgb_to_linear(rgba[..., :3])
        elif not (getattr(settings, "is_data", False) or _is_linear_space(space)):
            notes.append(f"colour space '{space}' not converted (read as linear)")
    return np.ascontiguousarray(rgba, np.float32), notes


class TextureCollector:
    """The scene's texture table: one row per distinct Blender image."""

    def __init__(self):
        self.names: list[str] = []
        self.images: list[np.ndarray] = []
        self.infos: list[TextureInfo] = []
        self.warnings: list[str] = []
        self._index: dict = {}

    def index_of(self, image, material_name: str) -> tuple[int, TextureInfo]:
        key = image.original.name_full if hasattr(image, "original") else image.name_full
        row = self._index.get(key)
        if row is not None:
            return row, self.infos[row]
        pixels, notes = read_image(image)
        if pixels is None:
            self.warnings.append(f"Image '{image.name}' (material '{material_name}') is missing or "
                                 f"cannot be loaded: rendered magenta")
            pixels = MAGENTA.copy()
        for note in notes:
            self.warnings.append(f"Image '{image.name}' (material '{material_name}'): {note}")
        alpha = pixels[..., 3]
        settings = image.colorspace_settings
        data = bool(getattr(settings, "is_data", False))
        mode = getattr(image, "alpha_mode", "STRAIGHT")
        associates = bool((alpha < 1.0).any()) and not data and mode not in {"CHANNEL_PACKED", "NONE"}
        info = TextureInfo(mean_color=tuple(float(x) for x in pixels[..., :3].reshape(-1, 3).mean(axis=0)),
                           mean_alpha=float(alpha.mean()), associates=associates)
        row = len(self.names)
        self._index[key] = row
        self.names.append(image.name)
        self.images.append(pixels)
        self.infos.append(info)
        return row, info

    @property
    def nbytes(self) -> int:
        return int(sum(a.nbytes for a in self.images))

    def table(self):
        """A ``TextureTable`` (None when the core does not define one yet, or no images)."""
        try:
            from ercuts_core.shading.textures import TextureTable
        except ImportError:
            return None
        return TextureTable(names=tuple(self.names), images=tuple(self.images))
