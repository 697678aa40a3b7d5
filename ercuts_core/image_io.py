"""Image output: linear EXR through OpenEXR, and an sRGB PNG preview; both written atomically
(:mod:`ercuts_core.atomic`: a failed or cancelled render never leaves a truncated file nor
overwrites a good one with a partial one; permissions as a plain ``open`` would give).
"""
from __future__ import annotations

import os
import struct
import zlib

import numpy as np
from numpy.typing import NDArray

from .atomic import atomic_path


def write_exr(path: str | os.PathLike, rgba: NDArray, extra: dict[str, NDArray] | None = None) -> None:
    """Write a float32 (h, w, 4) linear RGBA image (top row first) as a ZIP-compressed EXR.

    ``extra`` adds more channels, e.g. {'depth.Z': (h, w)} or {'normal': (h, w, 3)}.
    """
    import OpenEXR

    channels = {"RGBA": np.ascontiguousarray(rgba, np.float32)}
    for name, arr in (extra or {}).items():
        channels[name] = np.ascontiguousarray(arr, np.float32)
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    with atomic_path(path, ".exr") as tmp:
        OpenEXR.File(header, channels).write(tmp)


def read_exr(path: str | os.PathLike) -> dict[str, NDArray]:
    """Channels of an EXR file as float32 arrays (interleaved groups like 'RGBA' as (h, w, C))."""
    import OpenEXR

    with OpenEXR.File(os.fspath(path)) as f:
        return {k: np.array(v.pixels, np.float32) for k, v in f.channels().items()}


def linear_to_srgb(x: NDArray) -> NDArray:
    """IEC 61966-2-1 sRGB transfer function on [0, 1]-clipped linear values."""
    x = np.clip(x, 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)


def _png_chunk(tag: bytes, data: bytes) -> bytes:
    return struct.pack(">I", len(data)) + tag + data + struct.pack(">I", zlib.crc32(tag + data) & 0xFFFFFFFF)


def encode_png(rgb8: NDArray[np.uint8]) -> bytes:
    """Encode an (h, w, 3) uint8 image as PNG bytes (filter 0, zlib)."""
    h, w, _ = rgb8.shape
    raw = np.concatenate([np.zeros((h, 1), np.uint8), rgb8.reshape(h, w * 3)], axis=1).tobytes()
    ihdr = struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0)
    return (b"\x89PNG\r\n\x1a\n" + _png_chunk(b"IHDR", ihdr) +
            _png_chunk(b"IDAT", zlib.compress(raw, 6)) + _png_chunk(b"IEND", b""))


def write_png(path: str | os.PathLike, rgba: NDArray, exposure: float = 0.0) -> None:
    """Write an sRGB 8-bit preview of a linear image (Blender's 'Standard' view transform)."""
    rgb = np.asarray(rgba, np.float64)[..., :3] * 2.0**exposure
    rgb8 = np.round(linear_to_srgb(rgb) * 255.0).astype(np.uint8)
    with atomic_path(path, ".png") as tmp, open(tmp, "wb") as fh:
        fh.write(encode_png(rgb8))
