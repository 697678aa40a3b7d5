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

Alpha (Blender's ``alpha_mode``), as measured with Cycles in the same Blender (bpy 5.0.1:
an emission plane textured with a 50 % alpha image, Alpha output linked or not):

* byte images, STRAIGHT and PREMUL alike: ``image.pixels`` is what Cycles reads as straight
  colour (Cycles rendered EOTF(0.4) for a PREMUL pixel 0.4 with the Alpha output linked):
  used as they are.
* float buffers are premultiplied (ImBuf's convention: Cycles rendered 1.6 for a float pixel
  0.8 at alpha 0.5 with Alpha linked): un-premultiplied (RGB / alpha where alpha > 0).
* CHANNEL_PACKED: RGB and alpha are independent data: untouched. NONE: alpha set to 1.

Cycles' Image Texture outputs an *associated* (premultiplied) colour when its Alpha output
is not linked, except for data (Non-Color), channel-packed and alpha-less images; for byte
sRGB images the premultiplication happens on the encoded values (measured: 0.1326 =
EOTF(0.8 · 0.5), not 0.5 · EOTF(0.8) = 0.302). Such a texture node therefore reads a
second row, the image's *associated variant* (``index_of(..., associated=True)``): RGB =
EOTF(c·α) for byte sRGB, (linear c)·α otherwise, alpha unchanged. It exists only for images
with some alpha below 1 read that way.

Texture rows of byte sRGB images keep the 8-bit *encoded* values (:func:`read_texture`,
``TextureTable.srgb``): Cycles interpolates them encoded and decodes after the lookup
(``compress_as_srgb``), so Linear interpolation between different texels must too.

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


#: The EOTF of every 8-bit code value: byte images hold exactly k/255, so a table lookup is
#: exact (and ~20× faster than the power function on millions of texels).
_SRGB_LUT = srgb_to_linear(np.arange(256, dtype=np.float32) / np.float32(255.0))


def srgb_bytes_to_linear(c: np.ndarray) -> np.ndarray:
    """The sRGB EOTF of 8-bit values given as floats k/255 (rounded to the nearest code,
    as Cycles' byte textures are)."""
    codes = np.clip(np.rint(np.asarray(c, np.float32) * np.float32(255.0)), 0, 255).astype(np.uint8)
    return _SRGB_LUT[codes]


@dataclass
class TextureInfo:
    """What the shader compiler needs to know about a texture row."""

    mean_color: tuple
    mean_alpha: float


def _is_linear_space(name: str) -> bool:
    n = name.lower()
    return n.startswith("linear") or n in {"scene_linear", "scene linear"}


def read_image(image) -> tuple[np.ndarray | None, np.ndarray | None, list[str]]:
    """(straight, associated, notes): (H, W, 4) float32 linear straight-alpha pixels of
    ``image`` and Cycles' associated-colour variant (None when it equals the straight one:
    no alpha below 1, data, channel-packed or NONE alpha), or (None, None, notes) if the
    image cannot be loaded."""
    straight, associated, notes, _ = _read(image, decode=True)
    return straight, associated, notes


def read_texture(image) -> tuple[np.ndarray | None, np.ndarray | None, list[str], bool]:
    """As :func:`read_image` plus a flag, for texture rows: byte sRGB images come back
    *encoded* (flag True): straight = the 8-bit values, associated = the 8-bit premultiplied
    codes round(c·α·255)/255 (Cycles premultiplies the encoded bytes); the core decodes
    after interpolating (``TextureTable.srgb``)."""
    return _read(image, decode=False)


def _read(image, decode: bool):
    notes: list[str] = []
    try:
        w, h = (int(x) for x in image.size)
        if w <= 0 or h <= 0:
            return None, None, notes, False
        n = len(image.pixels)
        if n == 0 or n % (w * h):
            return None, None, notes, False
        channels = n // (w * h)
        buf = np.empty(n, np.float32)
        image.pixels.foreach_get(buf)
    except (RuntimeError, ReferenceError, ValueError, OSError):
        return None, None, notes, False
    px = buf.reshape(h, w, channels)
    if channels == 4:
        rgba = px  # a fresh buffer: modified in place
    else:
        rgba = np.ones((h, w, 4), np.float32)
        if channels == 1:
            rgba[..., :3] = px[..., :1]
        elif channels == 2:
            rgba[..., :3] = px[..., :1]
            rgba[..., 3] = px[..., 1]
        else:
            rgba[..., :3] = px[..., :3]
    is_float = bool(getattr(image, "is_float", False))
    if is_float and not np.isfinite(rgba).all():  # byte images cannot hold NaN
        notes.append("non-finite pixels replaced by 0")
        rgba = np.nan_to_num(rgba, nan=0.0, posinf=0.0, neginf=0.0)
    mode = getattr(image, "alpha_mode", "STRAIGHT")
    if mode == "NONE":
        rgba[..., 3] = 1.0
    elif is_float and mode != "CHANNEL_PACKED":
        a = rgba[..., 3:4]
        with np.errstate(divide="ignore", invalid="ignore"):  # alpha 0: colour kept as stored
            rgba[..., :3] = np.where(a > 0, rgba[..., :3] / np.where(a > 0, a, 1), rgba[..., :3])
    settings = image.colorspace_settings
    space = settings.name
    data = bool(getattr(settings, "is_data", False))
    srgb = not is_float and space == "sRGB"
    associated = None
    if not data and mode not in {"CHANNEL_PACKED", "NONE"} and (rgba[..., 3] < 1.0).any():
        associated = rgba.copy()
        associated[..., :3] *= rgba[..., 3:4]
        if srgb:  # Cycles premultiplies the 8-bit values, then linearises
            associated[..., :3] = srgb_bytes_to_linear(associated[..., :3]) if decode else \
                np.clip(np.rint(associated[..., :3] * np.float32(255.0)), 0, 255) / np.float32(255.0)
    if srgb and decode:
        rgba[..., :3] = srgb_bytes_to_linear(rgba[..., :3])
    elif not srgb and not is_float and not (data or _is_linear_space(space)):
        notes.append(f"colour space '{space}' not converted (read as linear)")
    if associated is not None and not srgb:
        associated[..., :3] = rgba[..., :3] * rgba[..., 3:4]
    return (np.ascontiguousarray(rgba, np.float32),
            None if associated is None else np.ascontiguousarray(associated, np.float32), notes,
            srgb and not decode)


def cache_key(image):
    """What an image's pixels depend on, for re-use across exports (the viewport re-exports
    on every edit); None when the image must be read again (unsaved edits — painting,
    ``pixels`` set from Python — sequences, movies, tiles)."""
    if image.is_dirty:
        return None
    source = image.source
    if image.packed_file is not None:
        origin = ("packed", image.packed_file.size)
    elif source == "FILE":
        import os

        import bpy

        path = bpy.path.abspath(image.filepath, library=image.library)
        try:
            st = os.stat(path)
            origin = (path, st.st_mtime_ns, st.st_size)
        except OSError:
            origin = (path, None, None)
    elif source == "GENERATED":
        origin = (image.generated_type, tuple(image.generated_color), image.generated_width,
                  image.generated_height, bool(image.use_generated_float))
    else:
        return None
    return (image.original.name_full, source, tuple(image.size), image.colorspace_settings.name,
            image.alpha_mode, bool(image.is_float), origin)


class TextureCollector:
    """The scene's texture table: one row per distinct Blender image.

    ``cache``: an optional dict kept by the caller between exports (the viewport session):
    images whose :func:`cache_key` is unchanged are not read again; after the export,
    :attr:`cache_out` holds the entries of this export's images (the caller replaces its
    cache with it, so the cache never outgrows one scene's textures).
    """

    def __init__(self, cache: dict | None = None):
        self.cache = cache
        self.cache_out: dict = {}
        self.reads = 0
        self.names: list[str] = []
        self.images: list[np.ndarray] = []
        self.srgb: list[bool] = []
        self.infos: list[TextureInfo] = []
        self.warnings: list[str] = []
        self._index: dict = {}
        self._pending: dict = {}

    def index_of(self, image, material_name: str, associated: bool = False) -> tuple[int, TextureInfo]:
        """Row of ``image`` (read on first use); ``associated``: the row Cycles' Color output
        reads when the node's Alpha output is unused (the same row when no alpha < 1)."""
        key = image.original.name_full
        rows = self._index.get(key)
        if rows is None:
            ckey = cache_key(image) if self.cache is not None else None
            cached = self.cache.get(ckey) if ckey is not None else None
            if cached is None:
                cached = read_texture(image)
                self.reads += 1
            if ckey is not None:
                self.cache_out[ckey] = cached
            straight, assoc, notes, srgb = cached
            if straight is None:
                self.warnings.append(f"Image '{image.name}' (material '{material_name}') is missing "
                                     f"or cannot be loaded: rendered magenta")
                straight, srgb = MAGENTA.copy(), False
            for note in notes:
                self.warnings.append(f"Image '{image.name}' (material '{material_name}'): {note}")
            rows = self._index[key] = [self._add(image.name, straight, srgb), None]
            self._pending[key] = (assoc, srgb)
        assoc, srgb = self._pending.get(key, (None, False))
        if associated and assoc is not None:
            if rows[1] is None:
                rows[1] = self._add(image.name + " (associated alpha)", assoc, srgb)
            return rows[1], self.infos[rows[1]]
        return rows[0], self.infos[rows[0]]

    def _add(self, name: str, pixels: np.ndarray, srgb: bool = False) -> int:
        flat = pixels.reshape(-1, 4)
        sample = flat[::max(1, len(flat) // 65536)]  # an estimate: ≤ 64 Ki texels suffice
        if srgb:   # the estimate is of linear colour
            sample = np.concatenate([srgb_bytes_to_linear(sample[:, :3]), sample[:, 3:]], axis=1)
        mean = sample.mean(axis=0, dtype=np.float64)
        info = TextureInfo(mean_color=tuple(float(x) for x in mean[:3]), mean_alpha=float(mean[3]))
        self.names.append(name)
        self.images.append(pixels)
        self.srgb.append(bool(srgb))
        self.infos.append(info)
        return len(self.names) - 1

    @property
    def nbytes(self) -> int:
        return int(sum(a.nbytes for a in self.images))

    def table(self):
        """A ``TextureTable`` (None when the core does not define one yet, or no images)."""
        try:
            from ercuts_core.shading.textures import TextureTable
        except ImportError:
            return None
        return TextureTable(names=tuple(self.names), images=tuple(self.images), srgb=tuple(self.srgb))
