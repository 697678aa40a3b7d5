"""Progressive Ercuts: a render is a sequence of iterations, each a complete, independent
Ercuts estimate (fresh rough BDPT samples and P, fresh chains, a new VPL set and light
tree, a new gather), averaged into the film — Progressive Lightcuts (Davidovič, Georgiev,
Slusallek 2012) applied to the paper's pipeline. Memory is that of one iteration, the
error keeps falling with the time spent, and iteration k is a deterministic function of
(seed, k) (:func:`iteration_seed`), so iterations can run anywhere and be merged.

Consistency: the VPL geometry clamp (a minimum distance) shrinks with the iteration index
as the radius of probabilistic progressive photon mapping (Knaus and Zwicker 2011:
r_k² = r_1² k^(α−1), α = 2/3), d_k = d_1 k^(−1/6) (:func:`iteration_clamp`): the clamping
bias of iteration k vanishes as k → ∞ while the variance added by the less-clamped VPLs
grows slowly enough that the average converges, the role of Progressive Lightcuts'
relaxed clamping.
"""
from __future__ import annotations

import numpy as np

from ...settings import RenderSettings

#: Knaus and Zwicker's α: the squared clamp distance shrinks as k^(α−1).
CLAMP_ALPHA = 2.0 / 3.0
#: A new iteration starts only if the time left is at least this share of the last one's
#: duration (the time is better left unused than spent on an iteration of a few samples).
START_SHARE = 0.5
#: An iteration is paced (its phases share the time left, so it finishes in time and fills
#: it) when the time left is under this many times the last iteration's duration: 1 +
#: START_SHARE, so an unpaced iteration of the last one's duration leaves time for another.
PACE_MARGIN = 1.0 + START_SHARE


def iteration_seed(seed: int, k: int) -> int:
    """The seed of iteration ``k``: ``seed`` itself for k = 0 (a one-iteration render is
    today's render), else a 31-bit seed derived from (seed, k) by numpy's SeedSequence."""
    if k == 0:
        return int(seed)
    return int(np.random.SeedSequence([int(seed) & 0xFFFFFFFF, k]).generate_state(1)[0] >> 1)


def iteration_clamp(clamp: float, k: int) -> float:
    """The VPL clamp distance of iteration ``k`` (0-based): clamp · (k+1)^((α−1)/2)."""
    return float(clamp) * (k + 1.0) ** ((CLAMP_ALPHA - 1.0) / 2.0)


#: Exponent of the growth of Ê1's samples per VPL over the iterations
#: (:func:`iteration_e1_samples`).
E1_GROWTH = 0.5


def iteration_e1_samples(e1_samples: int, k: int) -> int:
    """Ê1's light-traced samples per VPL in iteration ``k`` (0-based): N·(k+1)^E1_GROWTH.

    The normalisation divides by Ê1, and 1/Ê1 keeps a bias that shrinks with N per VPL
    after :func:`~.vpl.estimate_e1_allocated`'s correction: with the pilot-based (Jensen)
    correction the VPL image's energy was 0.9915 ± 0.0039 of its target at N = 256 in the
    glass-sphere scene (issue 15's test, 8 seeds), 0.998 at 512, 1.005 at 1024 — and the
    box's gathered light −1.7 % at 256 against PATH's (0.0844 against 0.0859), +0.6 % at
    512; re-measured at stop 42 that scene's gap did not fall as 1/N (0.987 / 0.989 at 64 /
    256 samples; 0.9935 ± 0.0033 over 24 seeds at 256), while the S-corridor's and door's
    did (:func:`~.vpl.jackknife_e1`). A bias of the same size in every iteration would
    survive any number of them; with N_k growing, the average over K iterations has the bias
    Σ_k b(N_k) / K → 0 (≈ 2c/(N·√K) for a term c/N; the consistency issue 13 asks for, as
    the shrinking clamp of :func:`iteration_clamp` does for the clamp), at a cost of
    (k+1)^½ times iteration 0's E1 phase. Paced iterations still cap it by their time."""
    return int(round(int(e1_samples) * (k + 1.0) ** E1_GROWTH))


def iteration_settings(settings: RenderSettings, k: int) -> RenderSettings:
    """``settings`` for iteration ``k``: its seed, clamp and Ê1 samples (the same object for
    k = 0); the shading positions come from :func:`stratified_jitter` with the render's seed
    and k."""
    if k == 0:
        return settings
    return settings.replace(seed=iteration_seed(settings.seed, k),
                            clamp=iteration_clamp(settings.clamp, k),
                            e1_samples=iteration_e1_samples(settings.e1_samples, k))


#: The R2 sequence's step (Roberts 2018): (1/g, 1/g²) with g the plastic number, the real
#: root of x³ = x + 1; its points fill the unit square with low discrepancy.
_PLASTIC = 1.324717957244746
R2_STEP = np.array([1.0 / _PLASTIC, 1.0 / _PLASTIC**2])


def stratified_jitter(n_pixels: int, samples: int, seed: int, k: int) -> np.ndarray:
    """(n_pixels·samples, 2) positions in the pixel for the shading points of iteration ``k``:
    point j of iteration k is element k·samples + j of the R2 sequence, rotated per pixel
    by a uniform random offset (Cranley-Patterson rotation, fixed by ``seed`` for the whole
    render). Each position is uniform in the pixel (the gather stays an unbiased estimate of
    the pixel integral), and over the iterations a pixel's positions are spread evenly, so
    the average anti-aliases edges faster than independent jitter."""
    rot = np.random.default_rng([int(seed) & 0xFFFFFFFF, 0x57A7]).random((n_pixels, 1, 2))
    index = (k * samples + np.arange(samples, dtype=np.float64))[None, :, None]
    return ((rot + index * R2_STEP) % 1.0).reshape(-1, 2)


def iteration_target(iterations: int, time_limited: bool) -> int | None:
    """How many iterations to render: ``iterations``, or None (until the time limit) for 0
    with a time limit; 0 without a time limit means one."""
    if iterations > 0:
        return iterations
    return None if time_limited else 1


def paced_iteration(k: int, target: int | None, clock, durations: list[float]) -> bool:
    """Pace iteration ``k`` (of ``target``, None: until the time limit) to its time? Under a
    time limit: with a target, every one (each gets its part of the time left); without, the
    first (its cost is unknown: it must finish in time) and any later one that the time left
    would not hold at full quality (under :data:`PACE_MARGIN` × the last duration). The
    others run at full quality, so a long budget is spent on many complete iterations, not
    one stretched one."""
    if clock.deadline is None:
        return False
    return target is not None or k == 0 or clock.remaining() < PACE_MARGIN * durations[-1]


def shrunk_settings(settings: RenderSettings, k: int, target: int | None, clock,
                    durations: list[float]) -> RenderSettings:
    """``settings`` for a later iteration the time left holds only in part (paced, no
    iteration target): its chains, and so its VPLs, in proportion to that part
    s = time left / the last iteration's duration (< :data:`PACE_MARGIN`, capped at 1), so it
    is a smaller complete estimate rather than one whose phases are cut short. Its VPL
    normalisation then keeps its samples per VPL: cut to the phase's share instead, Ê1 fell
    to 56 samples per VPL in the last, 7.3 s iteration of the directly lit scene at 60 s
    (160×120, seed 0), whose image had 10× the error of the 13 s iterations before it
    (relMSE 1.5e-3 against 1.5e-4) and doubled the render's (1.0e-4 against ≈ 3.8e-5 from
    the four full ones). The first iteration, whose cost is unknown, and renders with an
    iteration target are paced by their phases' shares alone."""
    if k == 0 or target is not None or clock.deadline is None or not durations:
        return settings
    s = clock.remaining() / max(durations[-1], 1e-9)
    if s >= 1.0:
        return settings
    s = max(s, 0.05)
    return settings.replace(chains_per_pixel=settings.chains_per_pixel * s,
                            max_chains=max(1, int(settings.max_chains * s)))


def iteration_end(k: int, target: int | None, clock, now: float) -> float | None:
    """Deadline of iteration ``k``: the clock's, or with ``target`` iterations 1/(target − k)
    of the time left (time an iteration does not need flows on to the next)."""
    if clock.deadline is None or target is None:
        return clock.deadline
    return now + max(clock.deadline - now, 0.0) / max(target - k, 1)


def fills_time(clock, started: float, now: float) -> bool:
    """Should a paced iteration begun at ``started`` spend the rest of the time limit (the
    stochastic gather's repeated passes) instead of leaving it to later iterations? Yes when
    no further iteration would start (:func:`more_iterations`): the time left is under
    :data:`START_SHARE` × its duration so far."""
    return clock.deadline is not None and clock.remaining() < START_SHARE * (now - started)


def more_iterations(done: int, target: int | None, clock, durations: list[float]) -> bool:
    """Start another iteration after ``done``? Not when ``target`` is reached, the render was
    cancelled, or (no target) the time left is under :data:`START_SHARE` of the last
    iteration's duration."""
    if clock.cancelled or (target is not None and done >= target):
        return False
    if target is None:
        return clock.remaining() >= START_SHARE * durations[-1]
    return True
