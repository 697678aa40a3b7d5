"""Progressive Ercuts (``RenderSettings.iterations``, :mod:`ercuts_core.integrators.ercuts.
progressive`): iterations are independent, deterministic functions of (seed, k), averaged
with equal weights; the VPL clamp shrinks with k; with ``iterations=0`` the render keeps
iterating until the time limit and never shows an unfinished iteration."""
from __future__ import annotations

import numpy as np
import pytest

from benchmarks.metrics import relmse
from ercuts_core import RenderSettings, render
from ercuts_core.integrators.ercuts.progressive import (CLAMP_ALPHA, iteration_clamp, iteration_e1_samples,
                                                        iteration_seed, iteration_settings, iteration_target)
from ercuts_core.scenes import closed_room

FAST = dict(integrator="ERCUTS", rough_samples=4, chain_length=20, chains_per_pixel=0.5, direct_samples=8)


def test_iteration_seeds_and_clamps():
    assert iteration_seed(7, 0) == 7                          # one iteration = today's render
    seeds = [iteration_seed(7, k) for k in range(1, 50)]
    assert len(set(seeds)) == 49 and all(0 <= s < 2**31 for s in seeds)
    assert iteration_seed(7, 3) == iteration_seed(7, 3) != iteration_seed(8, 3)
    # d_k = d_1 k^((α−1)/2) (1-based k): the squared distance falls as k^(α−1)
    assert iteration_clamp(0.02, 0) == 0.02
    assert iteration_clamp(0.02, 7) ** 2 == pytest.approx(0.02**2 * 8 ** (CLAMP_ALPHA - 1))
    assert iteration_clamp(0.02, 10**6) < 0.002                # bias → 0 as k → ∞
    s = RenderSettings(seed=7)
    assert iteration_settings(s, 0) is s
    assert iteration_settings(s, 2).seed == iteration_seed(7, 2)
    # Ê1's samples grow as (k+1)^½: the mean of the iterations' 1/N_k (the order of 1/Ê1's
    # residual bias) falls as 2/(N·√K) → 0
    assert iteration_settings(s, 3).e1_samples == iteration_e1_samples(s.e1_samples, 3) == 2 * s.e1_samples
    K = 10_000
    mean_inverse = np.mean([1.0 / iteration_e1_samples(256, k) for k in range(K)])
    assert mean_inverse == pytest.approx(2.0 / (256 * np.sqrt(K)), rel=0.02)
    assert (iteration_target(3, False), iteration_target(0, True), iteration_target(0, False)) == (3, None, 1)
    with pytest.raises(ValueError, match="iterations"):
        RenderSettings(iterations=-1)
    with pytest.raises(ValueError, match="iteration_start"):
        RenderSettings(iteration_start=-1)


def test_which_iterations_are_paced():
    """Without a target (until the time limit) the first iteration is paced, later ones only
    when the time left is under PACE_MARGIN × the last duration; with a target every one is,
    to 1/(N − k) of the time left; a paced iteration fills its time only when it is the last
    or the time left is under START_SHARE × its duration so far."""
    from types import SimpleNamespace

    from ercuts_core.integrators.ercuts.progressive import (PACE_MARGIN, START_SHARE, fills_time,
                                                            iteration_end, paced_iteration)

    def clock(left):
        return SimpleNamespace(deadline=100.0, remaining=lambda: left)

    free = SimpleNamespace(deadline=None, remaining=lambda: float("inf"))
    assert not paced_iteration(0, None, free, []) and iteration_end(2, 4, free, 5.0) is None
    assert paced_iteration(0, None, clock(50.0), [])
    assert not paced_iteration(3, None, clock(PACE_MARGIN * 10.0 + 0.1), [10.0])
    assert paced_iteration(3, None, clock(PACE_MARGIN * 10.0 - 0.1), [10.0])
    assert paced_iteration(3, 5, clock(80.0), [1.0])
    assert iteration_end(1, 5, clock(80.0), 20.0) == pytest.approx(20.0 + 80.0 / 4)
    assert iteration_end(1, None, clock(80.0), 20.0) == 100.0
    assert fills_time(clock(START_SHARE * 10.0 - 0.1), started=0.0, now=10.0)
    assert not fills_time(clock(START_SHARE * 10.0 + 0.1), started=0.0, now=10.0)


def test_a_short_last_iteration_is_a_smaller_complete_one():
    """A later iteration that the time left holds only in part (s = time left / the last
    duration < 1, no iteration target) runs s of the chains (so of the VPLs), keeping its
    samples per VPL; the first iteration, a render with a target and one with time for a
    whole iteration keep the settings (the last 7.3 s iteration of the directly lit scene at
    60 s had 10× the others' error with Ê1 cut to 56 samples per VPL: progressive.py)."""
    from types import SimpleNamespace

    from ercuts_core.integrators.ercuts.progressive import shrunk_settings

    def clock(left):
        return SimpleNamespace(deadline=100.0, remaining=lambda: left)

    base = RenderSettings(chains_per_pixel=0.25, max_chains=16384)
    small = shrunk_settings(base, 4, None, clock(6.0), [12.0])
    assert small.chains_per_pixel == pytest.approx(0.125) and small.max_chains == 8192
    assert small.e1_samples == base.e1_samples and small.chain_length == base.chain_length
    assert shrunk_settings(base, 0, None, clock(6.0), []) is base              # cost unknown
    assert shrunk_settings(base, 4, 8, clock(6.0), [12.0]) is base             # a target: its share
    assert shrunk_settings(base, 4, None, clock(13.0), [12.0]) is base         # time for a whole one
    assert shrunk_settings(base, 4, None, SimpleNamespace(deadline=None, remaining=lambda: 1.0),
                           [12.0]) is base


def test_a_time_limit_is_spent_on_complete_iterations():
    """Until the time limit (iterations = 0) on a room whose iteration takes a fraction of the
    limit: several iterations, most of them unpaced (full quality). The limit is 16 unpaced
    iterations on this machine (at least 8 s; 13–17 iterations, 1–2 paced, measured on a loaded
    machine), so that a slow or loaded machine tests the same thing (a fixed 8 s gave a loaded
    CI run 7 iterations, 4 of them paced)."""
    scene = closed_room(16, 12)
    one = dict(FAST, seed=1, gather="STOCHASTIC", iterations=1)
    render(scene, RenderSettings(**one))                                   # JIT and caches
    t_one = render(scene, RenderSettings(**one)).timings["total"]
    r = render(scene, RenderSettings(**FAST, seed=1, gather="STOCHASTIC", time_limit=max(8.0, 16 * t_one)))
    st = r.stats
    assert st["iterations"] >= 3, st
    assert st["iterations_paced"] <= st["iterations"] / 2, st      # the first and the last few
    assert r.stopped_by in (None, "time_limit") and np.isfinite(r.image).all()


def test_stratified_shading_positions():
    """Each iteration's shading position is uniform in the pixel (the Cranley-Patterson
    rotation), and over 16 iterations a pixel's positions fill its quadrants evenly (2–6
    each in every pixel, measured), where independent uniform positions leave a quadrant
    with fewer than 2 or more than 6 in about half the pixels."""
    from ercuts_core.integrators.ercuts.progressive import stratified_jitter

    n = 4000
    first = stratified_jitter(n, 1, seed=9, k=0)
    assert first.shape == (n, 2) and (first >= 0).all() and (first < 1).all()
    assert abs(first.mean() - 0.5) < 3 * np.sqrt(1 / 12 / (2 * n))
    pts = np.stack([stratified_jitter(n, 1, seed=9, k=k) for k in range(16)], axis=1)   # (n, 16, 2)
    quad = (pts[..., 0] >= 0.5) * 2 + (pts[..., 1] >= 0.5)
    counts = np.stack([(quad == q).sum(axis=1) for q in range(4)], axis=1)
    assert counts.min() >= 2 and counts.max() <= 6
    rng = np.random.default_rng(1)
    rand = (rng.random((n, 16, 2)) >= 0.5)
    rq = np.stack([((rand[..., 0] * 2 + rand[..., 1]) == q).sum(axis=1) for q in range(4)], axis=1)
    assert np.mean((rq.min(axis=1) < 2) | (rq.max(axis=1) > 6)) > 0.3
    # samples per pixel continue the sequence: iteration 1 with 2 samples = elements 2 and 3
    two = stratified_jitter(n, 2, seed=9, k=1).reshape(n, 2, 2)
    np.testing.assert_allclose(two[:, 1], stratified_jitter(n, 1, seed=9, k=3), atol=1e-12)


def test_iterations_are_the_average_of_independent_renders():
    """Three iterations = the mean of three one-iteration renders of iterations 0, 1, 2
    (``iteration_start``: each a deterministic function of (seed, k), so a frame's
    iterations can be rendered apart and merged), to float32 rounding."""
    desc = closed_room(24, 18)
    base = RenderSettings(**FAST, seed=3)
    three = render(desc, base.replace(iterations=3))
    assert three.stats["iterations"] == 3 and not three.cancelled
    singles = [render(desc, base.replace(iteration_start=k)).image.astype(np.float64) for k in range(3)]
    np.testing.assert_allclose(three.image, np.mean(singles, axis=0), rtol=2e-6, atol=1e-7)
    assert three.stats["clamp_last_iteration"] == pytest.approx(iteration_clamp(base.clamp, 2))
    again = render(desc, base.replace(iterations=3))
    np.testing.assert_array_equal(three.image, again.image)
    parts = sum(three.aovs[k] for k in ("emission", "direct", "indirect"))
    np.testing.assert_allclose(parts, three.image[..., :3], rtol=1e-5, atol=1e-6)


def test_progress_rises_over_the_iterations():
    seen = []
    render(closed_room(16, 12), RenderSettings(**FAST, iterations=3),
           progress=lambda f, m: seen.append(f))
    assert np.all(np.diff(seen) >= -1e-12) and seen[-1] == pytest.approx(1.0, abs=0.02)
    assert min(f for f in seen if f > 1 / 3) < 2 / 3                 # the second iteration reports too


def test_until_the_time_limit_every_pixel_finished():
    """iterations=0 with a time limit: iterations continue while the time allows (several
    fit in the limit on this tiny room); the image is the average of completed iterations
    (one stopped by the limit is discarded): finite, and as bright as one iteration."""
    desc = closed_room(16, 12)
    one = render(desc, RenderSettings(**FAST, seed=5))
    res = render(desc, RenderSettings(**FAST, seed=5, iterations=0, time_limit=12.0))
    assert res.stats["iterations"] >= 2
    img = res.image[..., :3]
    assert np.isfinite(img).all()
    ratio = img.mean() / one.image[..., :3].mean()
    assert abs(ratio - 1) < 0.1, ratio
    assert res.stopped_by in (None, "time_limit")


@pytest.mark.slow
def test_error_falls_with_iterations():
    """relMSE against the converged path-traced reference falls with the iteration count
    (1 → 6 iterations, 3 seeds each: the median drops by at least a third; chain noise and
    the clamp bias both shrink)."""
    import os
    ref = np.load(os.path.join(os.path.dirname(__file__), "data", "closed_room_48x36_path_2048spp.npz"))["mean"]
    desc = closed_room(48, 36)

    def err(n, seed):
        return relmse(render(desc, RenderSettings(**FAST, seed=seed, iterations=n)).image[..., :3], ref[..., :3])

    e1 = np.median([err(1, s) for s in range(3)])
    e6 = np.median([err(6, s) for s in range(3)])
    assert e6 < 0.67 * e1, (e1, e6)


def test_gather_passes_fill_time_no_later_iteration_would_use():
    """The stochastic gather asks after every pass whether the iteration should fill its time
    (:meth:`~ercuts_core.integrators.ercuts.pacing.Schedule.fills_time`): when it turns true
    only after the ``stochastic_passes`` are done (the iteration's end drew near, so no later
    iteration would start), passes continue until the time left holds no more, instead of
    leaving it unused (measured before: 21 s of a 30 s budget)."""
    from types import SimpleNamespace

    from ercuts_core.integrators.ercuts.gather import PASS_START, Gather

    Q, passes_asked = 6, 3
    state = {"left": 10.0, "calls": 0}

    def run(k, show):
        state["left"] -= 1.0                            # each pass takes 1 s
        return np.full((2, Q, 3), float(k + 1)), None, None, Q

    def fills_time():
        state["calls"] += 1
        return state["left"] < 8.5                      # true once the asked passes are done

    sweep = SimpleNamespace(pts_all=np.arange(Q), run=run)
    schedule = SimpleNamespace(fills_time=fills_time, remaining=lambda: state["left"],
                               clock=SimpleNamespace(cancelled=False))
    gather = SimpleNamespace(settings=SimpleNamespace(stochastic_passes=passes_asked),
                             g=SimpleNamespace(pixel=np.zeros(Q), samples=1), interp=None)
    L0 = np.ones((2, Q, 3))
    mean, passes = Gather._more_passes(gather, sweep, L0, 1.0, schedule, lambda *a: None, np.ones(Q, bool))
    assert passes > passes_asked                         # the time was filled
    assert state["left"] <= PASS_START * 1.0                # until the time left held no pass
    n = int(passes)
    np.testing.assert_allclose(mean, np.mean(np.arange(1, n + 1)))   # the mean of the passes
    # without the late fill, exactly stochastic_passes passes
    state.update(left=10.0)
    schedule.fills_time = lambda: False
    _, passes = Gather._more_passes(gather, sweep, L0, 1.0, schedule, lambda *a: None, np.ones(Q, bool))
    assert passes == passes_asked
