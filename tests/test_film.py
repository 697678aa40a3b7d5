"""The film's accumulation (ercuts_core/film.py): a batch of samples lands on exactly the pixels
it names, repeated pixels add up, whichever way :meth:`Film._add` takes (a bincount over the
batch's span for camera samples, ``np.add.at`` for scattered splats)."""
from __future__ import annotations

import numpy as np
import pytest

from ercuts_core.camera import Window
from ercuts_core.film import ADD_SPAN, Film


def _reference(n: int, pix: np.ndarray, values: np.ndarray) -> np.ndarray:
    out = np.zeros((n,) + values.shape[1:])
    np.add.at(out, pix, values)
    return out


@pytest.mark.parametrize("scattered", [False, True])
def test_samples_add_up_on_their_pixels(scattered):
    """Camera samples of a batch in the middle of the film (consecutive pixels, each several
    times, the bincount path) or spread over it (the add.at path) accumulate like
    ``np.add.at`` into every accumulator, twice over (the batch adds to what is there)."""
    window = Window(0, 0, 64, 48)
    n, rng = window.n_pixels, np.random.default_rng(3)
    if scattered:
        pix = rng.choice(n, 40, replace=False)
        pix = np.r_[pix, pix[:7]]                     # some repeated
        assert pix.max() - pix.min() + 1 > ADD_SPAN * len(pix)
    else:
        pix = np.repeat(np.arange(1000, 1300), 3)     # a batch, 3 samples per pixel
        assert pix.max() - pix.min() + 1 <= ADD_SPAN * len(pix)
    parts = rng.random((3, len(pix), 3))
    L, alpha = parts.sum(axis=0), rng.random(len(pix))
    film = Film(window)
    for _ in range(2):
        film.add_samples(pix, L, alpha, parts=parts)
        film.add_aov("depth", pix, alpha[:, None])
    np.testing.assert_allclose(film.color, 2 * _reference(n, pix, L), rtol=1e-12)
    np.testing.assert_allclose(film.alpha, 2 * _reference(n, pix, alpha), rtol=1e-12)
    np.testing.assert_allclose(film.aov_sum["depth"], 2 * _reference(n, pix, alpha[:, None]), rtol=1e-12)
    for c in range(3):
        np.testing.assert_allclose(film.color_parts[c], 2 * _reference(n, pix, parts[c]), rtol=1e-12)


def test_splats_land_at_their_raster_positions():
    """Light-tracing splats anywhere in the window (with repeats, one outside) accumulate
    at their pixels, by path class (``color_parts`` holds them divided by the pixel count)."""
    window = Window(0, 0, 32, 24)
    n, rng = window.n_pixels, np.random.default_rng(5)
    raster = rng.random((50, 2)) * [32, 24]
    raster = np.r_[raster, raster[:5], [[40.0, 3.0]]]           # repeats, one outside
    L = rng.random((len(raster), 3))
    cls = rng.integers(0, 3, len(raster))
    film = Film(window)
    film.add_splats(raster, L, cls)
    pix = raster[:-1, 0].astype(int) + 32 * raster[:-1, 1].astype(int)
    np.testing.assert_allclose(film.splat, _reference(n, pix, L[:-1]), rtol=1e-12)
    for c in range(3):
        m = cls[:-1] == c
        np.testing.assert_allclose(film.color_parts[c], _reference(n, pix[m], L[:-1][m]) / n, rtol=1e-12)


def test_pooled_passes_are_averaged_over_all_passes_not_per_iteration():
    """Two iterations' films: their own parts are averaged per iteration, their pooled parts
    (ERCUTS's direct passes) over the passes of both — a 64-pass and a 258-pass iteration
    weigh 64:258, not 1:1 — and the light passes sum to the image."""
    rng = np.random.default_rng(3)
    w = Window(0, 0, 4, 3)
    films, own, mean = [], [], []
    for n in (64, 258):
        parts = rng.random((3, w.n_pixels, 3))
        direct = rng.random((3, w.n_pixels, 3))          # the iteration's mean of n passes
        f = Film(w)
        f.set_pixels(parts, np.ones(w.n_pixels), direct * n, n)
        films.append(f), own.append(parts), mean.append(direct)
    film = films[0]
    film.merge(films[1])
    want = (own[0] + own[1]) / 2 + (64 * mean[0] + 258 * mean[1]) / 322
    np.testing.assert_allclose(film.light_parts(), want, rtol=1e-12)
    rgb = film.image()[..., :3].reshape(-1, 3)
    np.testing.assert_allclose(rgb, want.sum(axis=0), rtol=1e-6)
    assert film.pooled_passes == 322 and film.passes_done == 2
    empty = Film(w)                     # no pooled passes: the plain mean of the iterations
    empty.set_pixels(own[0], np.ones(w.n_pixels), mean[0] * 0, 0)
    assert empty.pooled is None and empty.pooled_passes == 0
