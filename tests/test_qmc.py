"""The pass loop's randomised Sobol numbers (ercuts_core.qmc): uniform, stratified per
pixel over the passes, independent between pixels, and a lower error than independent
passes where the integrand is smooth."""
import warnings

import numpy as np
import pytest
from scipy import stats

from ercuts_core import qmc
from ercuts_core.qmc import MAX_DIMS, PassSequence


def _points(n_passes: int, pixels, dims: int, stream=(7, 0xD1), rng_seed=0) -> np.ndarray:
    """(n_passes, len(pixels), dims) numbers of ``pixels`` over the passes."""
    out = []
    for k in range(n_passes):
        u = PassSequence(stream, k).bind(np.asarray(pixels), np.random.default_rng([rng_seed, k]))
        out.append(u.take(np.arange(len(pixels)), dims))
    return np.array(out)


def test_numbers_are_uniform_in_every_dimension():
    u = _points(4, np.arange(5000), 8)            # 20 000 draws per dimension
    assert u.min() >= 0.0 and u.max() < 1.0
    for d in range(8):
        assert stats.kstest(u[..., d].ravel(), "uniform").pvalue > 1e-3, d


def test_a_pixels_points_are_stratified_over_the_passes():
    """The first 2^m passes of one pixel put exactly one point in every one of 2^m equal
    intervals of each dimension, and in every elementary box 2^a × 2^(m−a) of dimensions
    (0, 1) (a (0, m, 2)-net): the digital shift keeps Sobol's net property."""
    m = 6
    u = _points(1 << m, [12345], MAX_DIMS)[:, 0, :]          # (64, dims)
    for d in range(MAX_DIMS):
        counts = np.bincount((u[:, d] * (1 << m)).astype(int), minlength=1 << m)
        assert (counts == 1).all(), d
    for a in range(m + 1):
        cell = (u[:, 0] * (1 << a)).astype(int) * (1 << (m - a)) + (u[:, 1] * (1 << (m - a))).astype(int)
        assert (np.bincount(cell, minlength=1 << m) == 1).all(), a


def test_pixels_and_streams_are_independent():
    """Different pixels (and the same pixel in another stream) see unrelated shifts: the
    correlation of their numbers over 20 000 pairs is within 5 standard errors of 0."""
    a = _points(1, np.arange(20000), 4)[0]
    b = _points(1, np.arange(20000) + 1, 4)[0]
    c = _points(1, np.arange(20000), 4, stream=(8, 0xD1))[0]
    for x in (b, c):
        r = np.corrcoef(a.ravel(), x.ravel())[0, 1]
        assert abs(r) < 5 / np.sqrt(a.size)


def test_dimensions_past_the_sobol_ones_come_from_the_generator():
    pix = np.arange(10)
    u = PassSequence((1,), 3).bind(pix, np.random.default_rng(5))
    u.take(np.arange(10), MAX_DIMS - 1)
    last = u.take(np.arange(10), 3)                     # one Sobol dimension, two random ones
    g = np.random.default_rng(5).random((10, 2))
    assert np.array_equal(last[:, 1:], g)
    assert not np.array_equal(last[:, :1], g[:, :1])


def test_lanes_keep_their_pixels_numbers():
    """A subset of lanes (paths that survived a bounce) gets the numbers its pixels would have
    had in the full batch."""
    pix = np.arange(100, 200)
    full = PassSequence((3,), 9).bind(pix, np.random.default_rng(0))
    part = PassSequence((3,), 9).bind(pix, np.random.default_rng(0))
    lanes = np.array([3, 17, 50, 99])
    assert np.array_equal(full.take(np.arange(100), 5)[lanes], part.take(lanes, 5))


def test_error_is_below_independent_sampling_on_a_smooth_integrand():
    """∫∫ f over [0, 1)² for a smooth f, estimated per pixel from 64 passes: the pixels are
    independent replicates of the randomised estimator, so their RMSE is measured to ±5 %
    (1000 pixels). Independent sampling's RMSE is σ_f/8 exactly; randomised Sobol points do
    better on smooth integrands (Owen 1997); the bound asks for a 4× lower RMSE."""
    def f(u):
        return np.exp(u[..., 0]) * np.cos(2.0 * u[..., 1]) + u[..., 0] * u[..., 1]

    exact_x = (np.e - 1.0) * np.sin(2.0) / 2.0 + 0.25
    g = np.random.default_rng(1).random((400000, 2))
    sigma = f(g).std()
    u = _points(64, np.arange(1000), 2)
    est = f(u).mean(axis=0)                              # (1000,)
    rmse = np.sqrt(np.mean((est - exact_x) ** 2))
    assert abs(est.mean() - exact_x) < 5 * est.std() / np.sqrt(len(est))   # unbiased
    assert rmse < 0.25 * sigma / 8.0


@pytest.mark.parametrize("index", [0, 4095, 4096, 10000])
def test_sobol_points_across_blocks_match_scipy(index):
    with warnings.catch_warnings():          # (not a power of 2: only its last point is used)
        warnings.simplefilter("ignore", UserWarning)
        ref = qmc.qmc.Sobol(d=MAX_DIMS, scramble=False, bits=32).random(index + 1)[-1]
    assert np.array_equal(qmc.sobol_point(index), (ref * 2.0**32).astype(np.uint32))


def test_padded_points_are_stratified_within_and_over_the_passes():
    """Several light samples per pass (:meth:`PixelSequence.padded`): the n points of one
    pass put one point in each of n equal intervals of every dimension, and the n·N points of
    the first N passes of a pixel one in each of n·N intervals (the first n·N points of a
    digitally shifted Sobol sequence); the call consumes k dimensions as ``take`` does."""
    n, passes, k = 4, 16, 3
    pts = []
    for i in range(passes):
        u = PassSequence((7, 0xD1), i).bind(np.array([4321]), np.random.default_rng(i))
        u.take(np.arange(1), 2)
        pts.append(np.concatenate(u.padded(np.arange(1), k, n)))          # (n, k)
        assert u.dim == 2 + k
        v = PassSequence((7, 0xD1), i).bind(np.array([4321]), np.random.default_rng(i))
        v.take(np.arange(1), 2 + k)
        assert np.array_equal(u.take(np.arange(1), 2), v.take(np.arange(1), 2))
    for d in range(k):
        for p in pts:
            assert (np.bincount((p[:, d] * n).astype(int), minlength=n) == 1).all()
        every = np.concatenate(pts)[:, d]
        assert (np.bincount((every * n * passes).astype(int), minlength=n * passes) == 1).all(), d


def test_padded_runs_of_different_lengths_stay_a_prefix_of_the_sequence():
    """Two passes with two points and then seven with four, each run starting where the last
    ended (``start``), are the first 32 points: one in each of 32 intervals of every
    dimension. Every eighth point alone (a pass taking one of eight reserved points) is not:
    its first coordinates lie in one quarter (measured: passes taking two of eight reserved
    points covered half of it, which made the Cornell box's direct light 2.6× noisier)."""
    starts, pts = [(0, 2), (2, 2)] + [(4 + 4 * i, 4) for i in range(7)], []
    for i, (start, n) in enumerate(starts):
        u = PassSequence((5,), i).bind(np.array([77]), np.random.default_rng(i))
        pts.extend(u.padded(np.arange(1), 3, n, start))
    every = np.concatenate(pts)
    for d in range(3):
        assert (np.bincount((every[:, d] * 32).astype(int), minlength=32) == 1).all(), d
    sparse = np.concatenate([PassSequence((5,), i).bind(np.array([77]), np.random.default_rng(i))
                             .padded(np.arange(1), 3, 1, 8 * i) for i in range(32)])
    assert len(np.unique((sparse.reshape(-1, 3)[:, 0] * 4).astype(int))) == 1


def test_padded_points_differ_between_pixels_and_from_the_pass_dimensions():
    """Two pixels' padded points are unrelated (correlation over 4 × 5000 pairs within 5
    standard errors of 0), and differ from the numbers ``take`` gives for those dimensions."""
    pix = np.arange(10000)
    u = PassSequence((9,), 2).bind(pix, np.random.default_rng(0))
    a = np.concatenate(u.padded(np.arange(5000), 3, 4))
    b = np.concatenate(u.padded(np.arange(5000, 10000), 3, 4))
    assert abs(np.corrcoef(a.ravel(), b.ravel())[0, 1]) < 5 / np.sqrt(a.size)
    assert stats.kstest(a.ravel(), "uniform").pvalue > 1e-3
    t = PassSequence((9,), 2).bind(pix, np.random.default_rng(0)).take(np.arange(5000), 3)
    assert not np.allclose(a[:5000], t)
