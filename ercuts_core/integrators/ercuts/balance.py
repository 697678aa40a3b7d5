"""Where an iteration's spare time goes: another direct-light pass or another stochastic gather
pass, whichever lowers the image's expected error more per second (not in the paper).

An Ercuts image is the sum of two independent estimates that are both means of independent
passes: the direct-light passes (light seen directly or scattered once, and the paths through
mirrors and glass the VPLs cannot carry, :mod:`.integrator`) and the stochastic gather's passes
(:mod:`.gather`). The variance of a pixel's mean falls as v/n with the passes n, so one more
pass lowers the error E = Σ_p v_p/n by E/(n + 1). Choosing, pass after pass, the estimator
with the larger E/((n + 1)·τ) (τ its seconds per pass) spends the time where it buys the most,
which converges to the optimum allocation of a budget between independent estimators with
costs, n_i ∝ σ_i/√τ_i (Neyman's allocation with costs; Cochran, *Sampling Techniques*, 3rd
ed. 1977, §5.5). E is measured from the passes' own spread (the sample variance of every
pixel over the passes, :class:`PassVariance`) and weighted like the benchmarks' relMSE,
Σ_p var_p / (Y_p² + 0.01) / N_pixels with Y_p the pixel's current luminance. After its first
pass the gather's spread is not known yet; in a paced iteration a probe (the pass drawn again
at a spread 2 % of the points, :meth:`PassVariance.probe`) gives it, so the direct passes can
compete for the time of the gather's second pass already: with 256-node cuts two gather passes
took all of an iteration's spare time in Veach's room at 30 s (9 direct samples instead of 29;
relMSE 0.034 with, 0.015 without that wait). Until stop 46 only the iteration that fills the
render's time did so; the others made their two gather passes whatever the direct passes'
noise, and the mirror room's 60 s render (two iterations) had 18 direct passes and a relMSE of
0.114 (seed 0). Now an iteration that later ones follow lends the time of its second pass,
and no more, to the direct passes (which are pooled over the iterations, so none is wasted):
22 passes, 0.073. Unbounded, the direct passes took the whole 60 s of the directly lit scene
(one iteration, 1 183 passes: relMSE 3.0e-5 → 8.8e-5), for the greedy rule sees the gather's
passes, not the VPL set's variance that only more iterations average.

Why it matters: a mirror or a glass pane that throws the light of a bright wall onto the room
(paths the direct passes path-trace) makes the direct passes' variance dwarf the gather's,
and a scene lit mostly directly has little for the gather to do; both spent their spare time
on gather passes before.
"""
from __future__ import annotations

import time
from typing import Callable

import numpy as np
from numpy.typing import NDArray

#: The relMSE's regulariser (benchmarks/metrics.py): errors of dark pixels count as absolute.
REL_EPS = 0.01
#: Cost of a direct pass's camera ray, hit and BSDF sample over that of one more light sample
#: at the hit (c0/c1 of :func:`light_samples_for`): 160×120 passes with 1 and 16 light samples
#: took 43 and 265 ms in the directly lit scene (c0/c1 = 1.9), 31 and 171 ms in the Cornell
#: box (2.3).
LIGHT_SAMPLE_COST_RATIO = 2.0


class PassVariance:
    """Per-pixel running mean and spread of one estimator's passes (their luminance).

    Args:
        n: pixels.
    """

    def __init__(self, n: int):
        self.count = 0
        self.s1 = np.zeros(n)
        self.s2 = np.zeros(n)
        self._probe: tuple[NDArray, NDArray, float] | None = None

    def probe(self, pixels: NDArray, a: NDArray, b: NDArray, share: float) -> None:
        """The per-pass variance before a second pass, from a probe: two independent draws
        ``a``, ``b`` (k,) of the pass at ``pixels`` (k,), a spread subsample of ``share`` of
        the image's pixels (the others have no variance: no surface, nothing to gather).
        (a − b)²/2 is an unbiased estimate of a pixel's per-pass variance, and their mean over
        the subsample of the image's mean (:meth:`error`)."""
        d = np.asarray(a, np.float64) - np.asarray(b, np.float64)
        self._probe = (np.asarray(pixels), 0.5 * d * d, share)

    def add(self, y: NDArray) -> None:
        """One more pass: ``y`` (n,) the pixels' luminance in it."""
        y = np.asarray(y, np.float64)
        self.count += 1
        self.s1 += y
        self.s2 += y * y

    def mean(self) -> NDArray:
        """(n,) the pixels' mean luminance over the passes (0 before the first)."""
        return self.s1 / max(self.count, 1)

    def error(self, ref: NDArray) -> float:
        """The relMSE-weighted variance of the pixels' means, mean_p var_p / n / (ref_p² +
        :data:`REL_EPS`) (after one pass from the :meth:`probe`, else inf before two passes:
        the spread is unknown)."""
        n = self.count
        if n == 1 and self._probe is not None:
            pix, var, share = self._probe
            return share * float(np.mean(var / (np.asarray(ref)[pix] ** 2 + REL_EPS)))
        if n < 2:
            return np.inf
        return float(np.mean(self.per_pass() / n / (np.asarray(ref) ** 2 + REL_EPS)))

    def per_pass(self) -> NDArray:
        """(n,) the pixels' unbiased per-pass variance (two or more passes)."""
        n = self.count
        m = self.s1 / n
        return np.maximum(self.s2 / n - m * m, 0.0) * n / (n - 1)

    def gain(self, ref: NDArray, seconds: float) -> float:
        """Error removed per second by one more pass of ``seconds``: E/((n + 1)·τ)."""
        return self.error(ref) / (self.count + 1) / max(seconds, 1e-9)


def light_samples_for(pass_var: NDArray, within: NDArray, k: int, ref: NDArray, k_max: int) -> int:
    """How many light samples a direct pass takes at the first hit, by two-stage sampling's
    optimum (Cochran, *Sampling Techniques*, 3rd ed. 1977, §10.6): a pass with k light
    samples has the per-pixel variance σ_b² + σ_w²/k (σ_w² one light sample's variance at a
    hit, σ_b² what the pixel jitter and the BSDF sample add) and costs c0 + c1·k, so the
    variance × cost of the mean is least at k* = √((c0/c1)·σ_w²/σ_b²), c0/c1 =
    :data:`LIGHT_SAMPLE_COST_RATIO`. σ_w² and σ_b² are relMSE-weighted means over the pixels
    (weights 1/(``ref``² + :data:`REL_EPS`)) of ``within`` (h·w,), the pilot passes' mean
    within-hit variance (``PathIntegrator.light_spread`` / passes), and of ``pass_var`` (h·w,)
    − within/k, the pilot passes' per-pass variance with ``k`` light samples less the
    light's part. Returned as the power of two in 1 … ``k_max`` nearest to k* in log (the
    padded Sobol points of a pass stay a net). Soft shadows of a large panel (directly lit
    scene): σ_w²/σ_b² ≈ 12, k* ≈ 5; the Cornell box's small panel: ≈ 0.12, k* ≈ 0.5."""
    w = 1.0 / (np.asarray(ref, np.float64) ** 2 + REL_EPS)
    sw = float(np.mean(w * within))
    sb = float(np.mean(w * np.maximum(pass_var - within / k, 0.0)))
    if sw <= 0.0:
        return 1
    if sb <= 0.0:
        return k_max
    best = np.sqrt(LIGHT_SAMPLE_COST_RATIO * sw / sb)
    return int(min(k_max, 2 ** max(0, int(np.round(np.log2(max(best, 1e-9)))))))


def passes_at_equal_cost(samples: int, done: int, k_done: int, k: int) -> int:
    """Passes with ``k`` light samples that cost what ``samples`` passes with one would, less
    the ``done`` passes with ``k_done`` already made (a pass with k costs (c0 + c1·k)/(c0 + c1)
    of one with one, c0/c1 = :data:`LIGHT_SAMPLE_COST_RATIO`): ``direct_samples`` is a
    budget of passes at one light sample each, so more light samples per pass take no time
    from the other phases. At least 1."""
    r = LIGHT_SAMPLE_COST_RATIO
    left = samples - done * (r + k_done) / (r + 1.0)
    return max(1, int(np.floor(left * (r + 1.0) / (r + k) + 1e-9)))


class DirectRival:
    """The direct-light passes as the gather's rival for spare time (module docstring).

    Args:
        run: ``run() -> bool`` renders one more direct pass into the direct film (adding its
            pixels' luminance to ``variance``); False when it was cut short.
        variance: the direct passes' :class:`PassVariance` so far.
        seconds: the duration of one direct pass so far (mean).
    """

    def __init__(self, run: Callable[[int], bool], variance: PassVariance, seconds: float):
        self.run, self.variance, self.seconds = run, variance, seconds
        self.extra = 0                 # passes added for the gather's spare time

    def gain(self, ref: NDArray) -> float:
        return self.variance.gain(ref, self.seconds)

    def step(self) -> bool:
        """One more direct pass; False when it could not be completed."""
        t0 = time.perf_counter()
        done = self.run()
        if done:
            self.seconds = 0.5 * (self.seconds + (time.perf_counter() - t0))
            self.extra += 1
        return done
