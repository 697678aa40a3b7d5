"""Time and progress of the Ercuts phases: time shares, deadlines, progress fractions and the
gather's pacing under a time limit (not in the paper, which has no time limit).

With ``time_limit`` > 0 each phase gets its share (:data:`SHARE`: rough BDPT 15 %, direct
light 5 % plus up to 45 % more as the rough image's light is direct, chains 30 %, VPL
normalisation 15 %, the rest for the gather) of the time *left*, so time an earlier phase
did not need flows on (:class:`Schedule`). The gather is paced by :class:`GatherPace`.
Progress messages start with the phase's name (api.md) and its fraction lies in the
phase's range of :data:`PHASES`.
"""
from __future__ import annotations

import time

import numpy as np

from .progressive import fills_time

#: Shares of the time limit per phase (the gather gets the rest); a phase's deadline gives
#: it its share of the time *left*, so time an earlier phase did not need flows on. The
#: direct-light share grows by :data:`DIRECT_SHARE_GROWTH` × the rough image's direct
#: fraction (the other shares shrink in proportion): a directly lit scene spends its time
#: on the direct passes, a corridor lit around corners on the chains and the gather.
SHARE = {"bdpt": 0.15, "direct": 0.05, "chains": 0.30, "vpl": 0.15}
DIRECT_SHARE_GROWTH = 0.45
#: Progress fractions (start, end) of each phase over the whole render (messages start
#: with the phase name, api.md); roughly the phases' time shares at default settings.
PHASES = {"BDPT": (0.0, 0.22), "Direct light": (0.22, 0.25), "ER chains": (0.25, 0.35),
          "VPLs": (0.35, 0.4), "Light tree": (0.4, 0.42), "Lightcuts": (0.42, 1.0)}
#: Largest lightcut error threshold the time limit may ask for; past it the cut size is
#: capped instead (cuts of a few clusters show their representatives as streaks).
MAX_PACED_ERROR = 0.25


class Schedule:
    """Deadlines and progress fractions of one Ercuts render (module docstring).

    Args:
        clock: the render's :class:`~ercuts_core.integrators.base.Clock`.
        direct_vpls: the paper's direct light by VPLs (no direct-light phase).
        paced: the phases share the time left (the first iteration); False: no phase
            deadlines and no gather pacing (later iterations run at full quality and are
            abandoned if the time limit passes).
        span: (start, end) of the render's progress that this iteration covers (iteration k
            of N: (k/N, (k+1)/N)); None: progress is the share of the time limit used (as
            many iterations as the time allows).
        end: this iteration's own deadline (``time.perf_counter()`` seconds; default: the
            clock's): with N iterations asked for, iteration k gets 1/(N − k) of the time left.
        last: no iteration follows this one (it may fill its time: :meth:`fills_time`).
    """

    def __init__(self, clock, direct_vpls: bool, paced: bool = True,
                 span: tuple[float, float] | None = (0.0, 1.0), end: float | None = None,
                 last: bool = False):
        self.clock = clock
        self.direct_vpls = direct_vpls
        self.paced = paced and clock.deadline is not None
        self.span = span
        self.share = dict(SHARE)       # time shares of this render
        self.started = time.perf_counter()
        self.end = clock.deadline if end is None or clock.deadline is None else min(end, clock.deadline)
        self.last = last

    def grow_direct(self, f_direct: float) -> None:
        """Give the direct-light phase :data:`DIRECT_SHARE_GROWTH` × ``f_direct`` (the rough
        image's direct fraction) more of the time."""
        self.share["direct"] = SHARE["direct"] + DIRECT_SHARE_GROWTH * min(max(f_direct, 0.0), 1.0)

    def fraction(self, phase: str, f: float) -> float:
        """Progress over the whole render of fraction ``f`` of ``phase`` (:data:`PHASES`
        within :attr:`span`; the time used without a span)."""
        if self.span is None:
            clock = self.clock
            return min(max((time.perf_counter() - clock.start) / (clock.deadline - clock.start), 0.0), 1.0)
        lo, hi = PHASES[phase]
        g = lo + (hi - lo) * min(max(f, 0.0), 1.0)
        return self.span[0] + (self.span[1] - self.span[0]) * g

    def deadline(self, phase: str) -> float | None:
        """End of ``phase``'s share (:data:`SHARE`) of the time left, or None without a limit."""
        if not self.paced:
            return None
        share = self.share
        order = [p for p in share if p != "direct" or not self.direct_vpls]
        later = sum(share[p] for p in order[order.index(phase):])
        gather = 1.0 - sum(SHARE[p] for p in order)
        now = time.perf_counter()
        return now + max(self.end - now, 0.0) * share[phase] / (later + gather)

    def remaining(self) -> float:
        """Seconds the pacing may plan with: those left of this iteration's time (:attr:`end`),
        inf when not :attr:`paced`."""
        return self.end - time.perf_counter() if self.paced else float("inf")

    def fills_time(self) -> bool:
        """Spend the rest of this iteration's time (repeated stochastic gather passes)? Only
        when paced, and when it is the :attr:`last` or no later iteration would start
        (:func:`~.progressive.fills_time`)."""
        return self.paced and (self.last or fills_time(self.clock, self.started, time.perf_counter()))

    def report(self, phase: str, f: float, message: str) -> bool:
        """Report fraction ``f`` of ``phase``; False once cancelled or past the time limit."""
        return self.clock.report(self.fraction(phase, f), message)

    def alive(self, deadline: float | None, phase: str, f: float, label: str) -> bool:
        """Report ``f`` of ``phase`` as ``"{phase} {f}% {label}"``; False once cancelled, past
        the time limit or past the phase's ``deadline``."""
        ok = self.report(phase, f, f"{phase} {100 * f:.0f}% {label}")
        return ok and (deadline is None or time.perf_counter() < deadline)


class GatherPace:
    """Lightcut error threshold and cut cap for the next gather batch under a time limit.

    After each batch the cost per point c at the current threshold ε is measured and the
    rest is projected, T = c·left. Lightcut cost falls roughly as 1/ε (cut sizes in
    ``benchmarks/results/lightcuts_scaling.md``), so ε ← ε·T/(0.9·remaining) keeps the
    gather on schedule in both directions, within [``max_error``, :data:`MAX_PACED_ERROR`];
    only when even that ε is too slow is the cut size capped (cap ← mean cut·0.9·remaining/T),
    and the cap is lifted before ε is lowered. Without a time limit nothing changes.
    """

    def __init__(self, max_error: float, max_cut_size: int):
        self.min_error, self.max_cut_size = max_error, max_cut_size
        self.error, self.cap = max_error, max_cut_size
        self.points_paced = 0          # points gathered with a raised threshold or a cap
        self.largest_error, self.smallest_cap = max_error, max_cut_size

    def update(self, n: int, seconds: float, mean_cut: float, left: int, remaining: float) -> None:
        """Pace the next batch from the one just gathered (``n`` points in ``seconds`` with
        the current threshold and cap, mean cut ``mean_cut``; ``left`` points to go)."""
        if self.error > self.min_error or self.cap < self.max_cut_size:
            self.points_paced += n
        if n == 0 or left == 0 or not np.isfinite(remaining):
            return
        ratio = seconds / n * left / max(0.9 * remaining, 1e-6)   # > 1: behind schedule
        if ratio > 1.0 and self.error >= MAX_PACED_ERROR:
            self.cap = int(max(1, min(self.cap, mean_cut / ratio)))
        elif ratio < 1.0 and self.cap < self.max_cut_size:
            self.cap = int(min(self.max_cut_size, max(self.cap + 1, self.cap / ratio)))
        else:
            self.error = float(np.clip(self.error * ratio, self.min_error, MAX_PACED_ERROR))
        self.largest_error = max(self.largest_error, self.error)
        self.smallest_cap = min(self.smallest_cap, self.cap)

    def record(self, stats: dict, done: int) -> None:
        """Stats of a paced gather: the largest threshold and smallest cap used, and the
        share of the ``done`` points gathered with either."""
        if self.points_paced:
            stats["paced_points_for_time_limit"] = self.points_paced / max(done, 1)
        if self.largest_error > self.min_error:
            stats["max_error_for_time_limit"] = self.largest_error
        if self.smallest_cap < self.max_cut_size:
            stats["cut_cap_for_time_limit"] = self.smallest_cap
