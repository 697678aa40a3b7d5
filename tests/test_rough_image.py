"""The rough BDPT image's full-resolution film (step 1): nearest low-resolution pixel, built
once per state of the rough film (the preview, the gather's fallback and a cancel share it)."""
import numpy as np

from ercuts_core.camera import Window
from ercuts_core.film import Film
from ercuts_core.integrators.ercuts.initialization import RoughImage


def _low_film(rng) -> Film:
    low = Film(Window(0, 0, 4, 2))
    parts = rng.random((3, 8, 3))
    low.set_pixels(parts, np.ones(8))
    return low


def test_full_film_is_the_nearest_low_pixel_and_cached_per_state():
    rng = np.random.default_rng(3)
    low = _low_film(rng)
    rough = RoughImage(low, Window(0, 0, 8, 4), (8, 4), (4, 2))
    full = rough.full_film()
    img_low, img_full = low.image(), full.image()
    # Each 2×2 block of full pixels shows its low-resolution pixel.
    np.testing.assert_array_equal(img_full[::2, ::2], img_low)
    np.testing.assert_array_equal(img_full[1::2, 1::2], img_low)
    assert rough.full_film() is full
    # Another pass changes the rough film: the full film is rebuilt from it.
    extra = Film(low.window)
    extra.set_pixels(rng.random((3, 8, 3)), np.ones(8))
    low.merge(extra)
    again = rough.full_film()
    assert again is not full
    np.testing.assert_allclose(again.image()[::2, ::2], low.image())


def test_fill_equals_merging_the_full_film_and_partial_parts_match():
    rng = np.random.default_rng(4)
    low = _low_film(rng)
    rough = RoughImage(low, Window(0, 0, 8, 4), (8, 4), (4, 2))
    filled, merged = Film(rough.full), Film(rough.full)
    rough.fill(filled)
    merged.merge(rough.full_film())
    np.testing.assert_array_equal(filled.image(), merged.image())
    assert filled.passes_done == merged.passes_done == 1
    pix = np.array([0, 5, 31])
    parts, alpha = rough.full_parts(pix)
    np.testing.assert_array_equal(parts, rough.full_film().light_parts()[:, pix])
    np.testing.assert_array_equal(alpha, np.ones(3))
    # A film that already holds a pass gets the rough image added as one more.
    rough.fill(filled)
    assert filled.passes_done == 2
    np.testing.assert_allclose(filled.image(), merged.image())
