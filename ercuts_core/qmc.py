"""Randomised quasi-Monte Carlo numbers for the camera samples of the pass loop.

Pass k of a render draws, for every pixel p, the k-th point of a Sobol sequence (Sobol 1967;
direction numbers of Joe and Kuo 2008, through ``scipy.stats.qmc.Sobol``), randomised by a
per-pixel random *digital shift*: each 32-bit coordinate is XORed with a hash of (stream, p,
dimension) (Owen 2003, "Quasi-Monte Carlo sampling", §5; pbrt-v3's ``SobolSampler`` scrambles
the same way). Every point is uniform in [0, 1)^d, so each pass stays an unbiased estimate
(the digital shift is a bijection of the 32-bit grid and the shifts are independent of the
scene); over the passes a pixel's points form a (t, s)-sequence in base 2, so its pixel,
light and BSDF samples are stratified jointly, where independent passes clump. Soft shadows
of a large panel and glossy highlights converge faster than at the Monte Carlo rate 1/N
(Owen 1997: variance O(N^-1-2/d) for piecewise smooth integrands; measured in
``benchmarks/bench_qmc.py``).

Dimensions are consumed in call order by :meth:`PixelSequence.take` (a path tracer draws its
camera jitter, then per bounce its light, BSDF and roulette numbers); dimensions past
:data:`MAX_DIMS` come from the pass's pseudo-random generator: Sobol's later dimensions
stratify little at the pass counts of a render, and that part of a path carries little of
the image's variance.
"""
from __future__ import annotations

from functools import lru_cache

import numpy as np
from numpy.typing import NDArray
from scipy.stats import qmc

#: The pass loop draws its numbers from this module; False is the ablation, independent
#: pseudo-random passes (``benchmarks/bench_qmc.py``).
ENABLED = True
#: Sobol dimensions per sample: camera jitter (2), lens (2), then light (3), BSDF (3) and
#: roulette (1) numbers for the first bounces; later numbers are pseudo-random.
MAX_DIMS = 24
#: Sobol points are generated in blocks of this many (a power of two: the first 2^m points
#: of a Sobol sequence are a (t, m, s)-net).
_BLOCK = 1 << 12
_SCALE = 1.0 / 4294967296.0      # 2^-32
_M64 = np.uint64(0xFFFFFFFFFFFFFFFF)


@lru_cache(maxsize=64)
def _sobol_block(block: int) -> NDArray:
    """(_BLOCK, MAX_DIMS) uint32: points block·_BLOCK … (block + 1)·_BLOCK − 1 of the
    unscrambled Sobol sequence as 32-bit integers (exact: scipy's floats are k/2^32)."""
    gen = qmc.Sobol(d=MAX_DIMS, scramble=False, bits=32)
    if block:
        gen.fast_forward(block * _BLOCK)
    return (gen.random(_BLOCK) * 4294967296.0).astype(np.uint32)


def sobol_point(index: int) -> NDArray:
    """(MAX_DIMS,) uint32: point ``index`` of the unscrambled Sobol sequence."""
    return _sobol_block(index // _BLOCK)[index % _BLOCK]


def mix64(x: NDArray) -> NDArray:
    """SplitMix64's finaliser (Steele, Lea, Flood 2014) on uint64 arrays: a bijective hash whose
    every output bit depends on every input bit."""
    x = np.asarray(x, np.uint64)
    with np.errstate(over="ignore"):
        x = (x ^ (x >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
        x = (x ^ (x >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
        return x ^ (x >> np.uint64(31))


def stream_key(words: tuple[int, ...]) -> int:
    """A 64-bit key of the integers ``words`` (a render's seed and a phase's key)."""
    h = np.uint64(0x9E3779B97F4A7C15)
    with np.errstate(over="ignore"):
        for w in words:
            h = mix64(np.uint64(h) ^ (np.uint64(int(w) & 0xFFFFFFFFFFFFFFFF) + np.uint64(0x9E3779B97F4A7C15)))
    return int(h)


def digital_shifts(key: int, pixels: NDArray, dims: NDArray) -> NDArray:
    """(len(pixels), len(dims)) uint32 random digital shifts of ``pixels`` (N,) int in
    dimensions ``dims`` (k,) int, a hash of (``key``, pixel, dimension)."""
    p = np.asarray(pixels, np.uint64)[:, None]
    d = np.asarray(dims, np.uint64)[None, :]
    with np.errstate(over="ignore"):
        h = mix64((p * np.uint64(0x100000001B3)) ^ (d << np.uint64(40)) ^ np.uint64(key))
        h = mix64(h + np.uint64(key))
    return (h >> np.uint64(32)).astype(np.uint32)


class PassSequence:
    """The quasi-random numbers of one pass: its Sobol point and the stream's key (a render's
    seed and the phase's key); :meth:`bind` gives the numbers of a batch of pixels.

    Args:
        stream: integers naming the stream (the same for all passes of a phase: a pixel's
            points over the passes are then one randomised Sobol sequence).
        index: the pass's index (its Sobol point).
    """

    def __init__(self, stream: tuple[int, ...], index: int):
        self.key = stream_key(tuple(stream))
        self.index = int(index)
        self.point = sobol_point(self.index)

    def bind(self, pixels: NDArray, rng: np.random.Generator) -> "PixelSequence":
        """The numbers of the camera samples at ``pixels`` (N,) of this pass; ``rng`` gives
        those past :data:`MAX_DIMS`."""
        return PixelSequence(self, np.asarray(pixels, np.int64), rng)


class PixelSequence:
    """Uniform numbers for a batch of camera samples, dimension by dimension (module
    docstring). Samples are addressed by *lane*: their index in the batch's pixel array."""

    def __init__(self, seq: PassSequence, pixels: NDArray, rng: np.random.Generator):
        self.seq, self.pixels, self.rng = seq, pixels, rng
        self.dim = 0

    def take(self, lanes: NDArray, k: int) -> NDArray:
        """(len(lanes), k) float64 in [0, 1): the next ``k`` dimensions of the samples
        ``lanes`` (N,) (indices into the batch); every call moves on by ``k`` dimensions for
        all samples, drawn or not, so a sample never sees a dimension twice."""
        lanes = np.asarray(lanes, np.int64)
        d0, self.dim = self.dim, self.dim + k
        out = np.empty((len(lanes), k))
        q = max(0, min(k, MAX_DIMS - d0))          # dimensions still from the Sobol point
        if q:
            dims = np.arange(d0, d0 + q)
            bits = self.seq.point[dims][None, :] ^ digital_shifts(self.seq.key, self.pixels[lanes], dims)
            out[:, :q] = bits * _SCALE
        if q < k:
            out[:, q:] = self.rng.random((len(lanes), k - q))
        return out

    def padded(self, lanes: NDArray, k: int, n: int, start: int | None = None) -> list[NDArray]:
        """``n`` points per sample for the next ``k`` ≤ :data:`MAX_DIMS` dimensions, which this
        call consumes as :meth:`take` does: point j (len(lanes), k) is point ``start`` + j
        (default: pass i·n + j) of another Sobol sequence in k dimensions, digitally shifted per
        pixel by a stream of its own (a *padded* sequence, Kollig & Keller 2002, pbrt-v4's
        ``PaddedSobolSampler``). When the passes take consecutive runs of it — ``start`` the
        points the earlier passes took — a pixel's points are the first ones of one randomised
        Sobol sequence, so several light samples per pass stay stratified with one another and
        with those of earlier passes (runs with gaps are not: every eighth point alone puts its
        first coordinate in one quarter); each point is uniform, so every estimate
        from one is unbiased. They are not stratified jointly with the other dimensions."""
        lanes = np.asarray(lanes, np.int64)
        d0, self.dim = self.dim, self.dim + k
        key = stream_key((self.seq.key, 0x9ADD, d0))
        dims = np.arange(k)
        shift = digital_shifts(key, self.pixels[lanes], dims)
        start = self.seq.index * n if start is None else int(start)
        return [(sobol_point(start + j)[dims][None, :] ^ shift) * _SCALE for j in range(n)]
