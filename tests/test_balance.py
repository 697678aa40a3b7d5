"""Spare time between the stochastic gather's passes and the direct-light passes
(:mod:`ercuts_core.integrators.ercuts.balance`): the passes' spread, the probe that measures the
gather's variance after its first pass, and the choice between the two pass by pass."""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
from numpy.typing import NDArray

from ercuts_core.integrators.ercuts.balance import (LIGHT_SAMPLE_COST_RATIO, REL_EPS, DirectRival, PassVariance,
                                                  light_samples_for, passes_at_equal_cost)
from ercuts_core.integrators.ercuts.gather import Gather


def _expected(sigma: NDArray, ref: NDArray, n: int) -> float:
    return float(np.mean(sigma**2 / n / (ref**2 + REL_EPS)))


def test_pass_spread_estimates_the_variance_of_the_mean():
    """After n passes, error() is mean_p σ_p²/n/(ref_p² + ε) (the sample variance is
    unbiased). Tolerance: with m pixels the relative standard error of the mean of m
    (n−1)-degree χ² variances is √(2/((n−1)m)) ≈ 0.4 % for n = 8, m = 20 000; 5σ."""
    rng = np.random.default_rng(1)
    m, n = 20_000, 8
    mu = rng.uniform(0.1, 2.0, m)
    sigma = 0.3 * mu
    v = PassVariance(m)
    assert v.error(mu) == np.inf                  # nothing known yet
    v.add(mu + sigma * rng.standard_normal(m))
    assert v.error(mu) == np.inf                  # one pass, no probe: spread unknown
    for _ in range(n - 1):
        v.add(mu + sigma * rng.standard_normal(m))
    want = _expected(sigma, mu, n)
    assert v.error(mu) == pytest.approx(want, rel=5 * np.sqrt(2 / ((n - 1) * m)))
    assert v.gain(mu, 2.0) == pytest.approx(v.error(mu) / (n + 1) / 2.0)


def test_probe_estimates_one_pass_variance_from_a_subsample():
    """The probe: two independent draws at k of the image's pixels (a share of them; the
    others have nothing to gather). (a − b)²/2 per pixel is unbiased for σ²; the mean over
    k pixels estimates the image's mean (relative standard error √2/√k for equal weights:
    2.2 % at k = 4096; 5σ). A wrong factor (no 1/2, or no share) fails."""
    rng = np.random.default_rng(2)
    n_pixels, share = 40_000, 0.5
    ref = np.zeros(n_pixels)
    lit = rng.permutation(n_pixels)[: int(share * n_pixels)]      # the pixels with a surface
    ref[lit] = rng.uniform(0.5, 1.5, len(lit))
    sigma = np.zeros(n_pixels)
    sigma[lit] = 0.2 * ref[lit]
    k = 4096
    pix = lit[:k]
    a = ref[pix] + sigma[pix] * rng.standard_normal(k)
    b = ref[pix] + sigma[pix] * rng.standard_normal(k)
    v = PassVariance(n_pixels)
    v.add(ref + sigma * rng.standard_normal(n_pixels))
    v.probe(pix, a, b, share)
    want = _expected(sigma, ref, 1)
    assert v.error(ref) == pytest.approx(want, rel=5 * np.sqrt(2 / k))
    v.add(ref + sigma * rng.standard_normal(n_pixels))  # from two passes on: their spread
    assert v.error(ref) == pytest.approx(_expected(sigma, ref, 2), rel=0.05)


def _gather_and_rival(sigma_gather: float, sigma_direct: float, fills: bool, passes_asked: int = 2,
                      paced: bool = True):
    """A mock gather (passes of 1 s, per-point noise ``sigma_gather``, probe included) and a
    direct rival (passes of 1 s, noise ``sigma_direct``, 8 passes so far) over Q pixels, one
    point each; the iteration has 6 s left."""
    Q = 4096
    rng = np.random.default_rng(3)
    state = {"left": 6.0, "probe": 0}

    def draw():
        return 1.0 + sigma_gather * rng.standard_normal((2, Q, 3)) / 2

    def run(k, show):
        state["left"] -= 1.0
        return draw(), None, None, Q

    def probe(k):
        state["left"] -= 0.02
        state["probe"] += 1
        return draw(), k

    direct = PassVariance(Q)
    for _ in range(8):
        direct.add(1.0 + sigma_direct * rng.standard_normal(Q))

    def one_more():
        state["left"] -= 1.0
        direct.add(1.0 + sigma_direct * rng.standard_normal(Q))
        return True

    rival = DirectRival(one_more, direct, 1.0)
    sweep = SimpleNamespace(pts_all=np.arange(Q), run=run, probe=probe)
    schedule = SimpleNamespace(fills_time=lambda: fills, paced=paced, remaining=lambda: state["left"],
                               clock=SimpleNamespace(cancelled=False))
    gather = SimpleNamespace(settings=SimpleNamespace(stochastic_passes=passes_asked),
                             g=SimpleNamespace(pixel=np.arange(Q), samples=1), interp=None)
    gather._probe = lambda sw, L, spread: Gather._probe(gather, sw, L, spread)
    L0 = draw()
    _, passes = Gather._more_passes(gather, sweep, L0, 1.0, schedule, lambda *a: None,
                                    np.ones(Q, bool), rival)
    return passes, rival, state


def test_direct_passes_take_the_second_gather_pass_when_they_are_noisier():
    """In an iteration that fills its time, the probe after the first gather pass tells the
    balance the gather's variance, so a far noisier direct estimate (a mirror room's) gets
    the time of the gather's second pass already; before the probe it waited for
    ``stochastic_passes`` gather passes (Veach's room at 30 s: 1.9 gather passes, 9 direct
    samples instead of 29)."""
    passes, rival, state = _gather_and_rival(sigma_gather=0.05, sigma_direct=1.0, fills=True)
    assert state["probe"] == 1
    assert passes == 1.0 and rival.extra >= 4            # every further second went direct
    # the gather noisier: it keeps its passes, the rival gets nothing
    passes, rival, state = _gather_and_rival(sigma_gather=1.0, sigma_direct=0.05, fills=True)
    assert passes >= 5 and rival.extra == 0


def test_a_paced_iteration_that_later_ones_follow_lends_its_second_pass_too():
    """A paced iteration that does not fill the render's time (later iterations follow) also
    probes, and a far noisier direct estimate takes the time of the gather's second pass and no
    more (since stop 46: the direct passes are pooled over the iterations, so none is wasted;
    with no bound they took all of a 60 s render of the directly lit scene, one iteration of
    1 183 direct passes, relMSE 3.0e-5 → 8.8e-5, the VPL set's variance left unaveraged); a
    noisier gather makes its ``stochastic_passes`` and no more. Unpaced, it makes exactly
    those passes, with no probe and no direct pass taken from it, however noisy those are."""
    passes, rival, state = _gather_and_rival(sigma_gather=0.05, sigma_direct=1.0, fills=False)
    assert state["probe"] == 1 and rival.extra == 1 and passes == 1   # one 1 s pass for one 1 s pass
    passes, rival, state = _gather_and_rival(sigma_gather=1.0, sigma_direct=0.05, fills=False)
    assert state["probe"] == 1 and rival.extra == 0 and passes == 2
    passes, rival, state = _gather_and_rival(sigma_gather=0.05, sigma_direct=1.0, fills=False, paced=False)
    assert passes == 2 and rival.extra == 0 and state["probe"] == 0


@pytest.mark.parametrize("ratio, expected", [(12.0, 4), (0.12, 1), (0.8, 1), (3.0, 2), (100.0, 8), (1e4, 8)])
def test_light_samples_follow_two_stage_samplings_optimum(ratio, expected):
    """k* = √(c0/c1 · σ_w²/σ_b²) (Cochran §10.6), as the nearest power of two up to k_max:
    σ_w²/σ_b² = 12 (soft shadows) → √24 ≈ 4.9 → 4; 0.12 (sharp shadows) → 0.49 → 1; 0.8 → 1.3
    → 1; 3 → 2.4 → 2; capped at 8. The pilot's per-pass variance holds σ_w²/k; weights are
    the relMSE's: doubling the within-hit spread of the bright half alone barely moves it."""
    assert LIGHT_SAMPLE_COST_RATIO == 2.0
    n, k = 1000, 2
    ref = np.full(n, 0.5)
    sb = np.full(n, 0.01)
    sw = ratio * sb
    assert light_samples_for(sb + sw / k, sw, k, ref, 8) == expected


def test_light_samples_weigh_pixels_like_the_relmse():
    """Bright pixels whose variance is all light sampling count for little next to dark ones
    whose variance is all jitter (weights 1/(Y² + 0.01)): one light sample, and many where
    only the light's part exists; none with no light spread at all."""
    n, k = 1000, 2
    ref = np.where(np.arange(n) < n // 2, 10.0, 0.05)
    sw = np.where(ref > 1, 1.0, 0.0)
    sb = np.where(ref > 1, 0.0, 0.01)
    assert light_samples_for(sb + sw / k, sw, k, ref, 8) == 1
    assert light_samples_for(sw / k, sw, k, ref, 8) == 8
    assert light_samples_for(sb, np.zeros(n), k, ref, 8) == 1


def test_more_light_samples_mean_fewer_passes_at_the_same_cost():
    """A pass with k light samples costs (2 + k)/3 of one with one (c0/c1 = 2): 64 passes'
    budget less 2 pilot passes with 2 (8/3 of a pass) leaves 61.33 → 61 passes with 1, 46
    with 2, 30 with 4, 18 with 8; a spent budget still gets one."""
    assert [passes_at_equal_cost(64, 2, 2, k) for k in (1, 2, 4, 8)] == [61, 46, 30, 18]
    assert passes_at_equal_cost(3, 2, 2, 4) == 1
    assert passes_at_equal_cost(10, 0, 1, 1) == 10
