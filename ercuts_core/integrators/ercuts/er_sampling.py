"""Paper step 2 — ER sampling: Markov chains of equal length from bidirectional seed paths.

Energy redistribution [Cline, Talbot, Egbert 2005; Mitsuba 0.6 ``erpt``]: a seed path with
image energy e starts ⌊U + e/(N·e_d)⌋ chains of N steps; every step deposits the same energy
e_d = P/n (paper §3.2–3.3), here at the chain's current state after the accept/reject
decision (the unbiased "deposit at the current state" variant, algorithm.md §A.1). The
acceptance is the paper's eq. (1), a = min(1, f(y)T(x|y) / (f(x)T(y|x))), with f the
luminance of the measurement contribution restricted to paths whose x2 is a surface point.

Deposits are not splatted to pixels: each goes to the VPL at the state's x2 (paper §3.3).
A VPL is identified by its x2: every accepted move that changes x2 starts a new VPL, all
other moves (and rejections) add to the current one, and chains started from the same seed
share their first VPL — so "coinciding VPLs merge" by construction. Chains of all pixels
advance in lock-step: one mutation step of all chains is one batch per mutation type.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from ...sampling import luminance
from ...vecmath import dot
from .mutations import MUTATORS, NAMES, MutationContext, applicable
from .paths import PathBatch, contribution, is_target


@dataclass
class ChainResult:
    """VPL records produced by the chains.

    Attributes:
        position: (V, 3) x2 of each VPL [m]; normal: (V, 3) unit geometric normal at x2, facing
            x1 (the patch's emission axis, not a normal map's shading normal).
        count: (V,) number of deposits (each worth e_d of image energy).
        color_sum: (V, 3) sum over deposits of the relative colour (luminance 1) of the
            light leaving x2 toward x1.
        home: (V, 2) raster position of x1 when the VPL was created.
        proposed, accepted: (4,) per mutation (lens, caustic, multichain, bidirectional).
        deposits_per_pixel: (h·w,) chain states per window pixel (diagnostic image).
        n_chains, n_steps: chains run and steps per chain.
        nan_acceptances: acceptance values that were not finite (must stay 0).
        emitter: (V,) bool, x2 is the path's light vertex (k = 2: the VPL carries direct
            light from a surface emitter; else x2 scatters and it carries indirect light).
    """

    position: NDArray
    normal: NDArray
    count: NDArray
    color_sum: NDArray
    home: NDArray
    proposed: NDArray
    accepted: NDArray
    deposits_per_pixel: NDArray
    n_chains: int
    n_steps: int
    nan_acceptances: int = 0
    steps_done: int = 0
    stats: dict = field(default_factory=dict)
    emitter: NDArray | None = None

    @property
    def n_vpls(self) -> int:
        return len(self.count)


class _VPLStore:
    """Growable VPL attribute arrays."""

    def __init__(self, capacity: int):
        self.n = 0
        self.position = np.zeros((capacity, 3))
        self.normal = np.zeros((capacity, 3))
        self.home = np.zeros((capacity, 2))
        self.count = np.zeros(capacity)
        self.color_sum = np.zeros((capacity, 3))
        self.emitter = np.zeros(capacity, bool)

    def _grow(self, need: int) -> None:
        cap = len(self.count)
        if need <= cap:
            return
        new = max(need, 2 * cap)
        for name in ("position", "normal", "home", "count", "color_sum", "emitter"):
            old = getattr(self, name)
            arr = np.zeros((new,) + old.shape[1:], old.dtype)
            arr[:cap] = old
            setattr(self, name, arr)

    def add(self, paths: PathBatch) -> NDArray:
        """New VPLs at x2 of ``paths``; returns their ids."""
        m = len(paths)
        self._grow(self.n + m)
        ids = np.arange(self.n, self.n + m)
        x1, x2 = paths.p[:, 1], paths.p[:, 2]
        n = paths.ng[:, 2]
        flip = dot(n, x1 - x2) < 0
        self.position[ids] = x2
        self.normal[ids] = np.where(flip[:, None], -n, n)
        self.home[ids] = paths.raster
        self.emitter[ids] = paths.k == 2
        self.n += m
        return ids


def chain_starts(energy: NDArray, n_steps: int, e_d: float, rng: np.random.Generator) -> NDArray:
    """(S,) number of chains per seed: ⌊U + e/(N·e_d)⌋ (Cline et al. 2005, Alg. 2)."""
    if e_d <= 0:
        return np.zeros(len(energy), np.int64)
    return np.floor(rng.random(len(energy)) + energy / (n_steps * e_d)).astype(np.int64)


def _pick_mutation(app: NDArray, u: NDArray) -> NDArray:
    """(C,) index of a mutation chosen uniformly among the applicable ones (−1 if none)."""
    n_app = app.sum(axis=1)
    j = np.minimum((u * n_app).astype(np.int64), np.maximum(n_app - 1, 0))
    rank = np.cumsum(app, axis=1) - 1
    choice = np.where(app & (rank == j[:, None]), np.arange(app.shape[1])[None, :], 99).min(axis=1)
    return np.where(n_app > 0, choice, -1)


def run_chains(ctx: MutationContext, seeds: PathBatch, starts: NDArray, n_steps: int,
               enabled: tuple[bool, bool, bool, bool], rng: np.random.Generator,
               keep_going=lambda fraction: True, interrupt=None) -> ChainResult:
    """Run ``starts[i]`` chains of ``n_steps`` from each seed path, all in lock-step.

    Args:
        seeds: (S) seed paths (target class only); starts: (S,) chains per seed.
        enabled: switches for (lens, caustic, multichain, bidirectional).
        keep_going: ``keep_going(fraction) -> bool``; False stops after the current step
            (the deposits so far stay valid: every chain stopped at the same step).
        interrupt: optional ``interrupt(fraction) -> bool`` polled between the mutation
            groups of a step (a step of 10^5+ chains takes seconds); False abandons the
            step at once, without its deposits (a user cancel: the result is not used).
    """
    scene = ctx.scene
    window = scene.camera.window
    seed_of = np.repeat(np.arange(len(seeds)), starts)
    x = seeds.take(seed_of)
    C = len(x)
    store = _VPLStore(max(16, 4 * C))
    first = store.add(seeds)                       # one VPL per seed (shared by its chains)
    vpl = first[seed_of]
    f_x, c_x = contribution(scene, x, with_x2_light=True)
    y_x = luminance(f_x)
    rel_x = _relative(c_x)
    proposed = np.zeros(4, np.int64)
    accepted = np.zeros(4, np.int64)
    deposits = np.zeros(window.n_pixels)
    nan_count = 0
    steps_done = 0
    for step in range(n_steps if C else 0):
        choice = _pick_mutation(applicable(ctx, x, enabled), rng.random(C))
        abandoned = False
        for mut in range(4):
            rows = np.flatnonzero(choice == mut)
            if len(rows) == 0:
                continue
            if interrupt is not None and interrupt((step + mut / 4) / n_steps) is False:
                abandoned = True
                break
            prop = MUTATORS[mut](ctx, x.take(rows), rng)
            f_y, c_y = contribution(scene, prop.paths, with_x2_light=True)
            y_y = luminance(f_y)
            ok = prop.valid & is_target(scene, prop.paths, ctx.direct) & (y_x[rows] > 0)
            with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
                a = np.where(ok, np.minimum(1.0, y_y * prop.ratio / np.where(ok, y_x[rows], 1.0)), 0.0)
            bad = ~np.isfinite(a)
            nan_count += int(bad.sum())
            a[bad] = 0.0
            acc = rng.random(len(rows)) < a
            proposed[mut] += len(rows)
            accepted[mut] += int(acc.sum())
            if acc.any():
                r = rows[acc]
                moved = prop.paths.take(np.flatnonzero(acc))
                x.put(r, moved)
                y_x[r], rel_x[r] = y_y[acc], _relative(c_y[acc])
                new = prop.x2_changed[acc]
                if new.any():
                    vpl[r[new]] = store.add(moved.take(np.flatnonzero(new)))
        if abandoned:
            break
        # Deposit e_d at every chain's current state (its VPL and, for the diagnostic, its pixel).
        store.count[: store.n] += np.bincount(vpl, minlength=store.n)
        for c in range(3):
            store.color_sum[: store.n, c] += np.bincount(vpl, weights=rel_x[:, c], minlength=store.n)
        deposits += np.bincount(_pixel(window, x.raster), minlength=window.n_pixels)
        steps_done = step + 1
        if not keep_going(steps_done / n_steps):
            break
    n = store.n
    return ChainResult(store.position[:n], store.normal[:n], store.count[:n], store.color_sum[:n],
                       store.home[:n], proposed, accepted, deposits, C, n_steps, nan_count, steps_done,
                       {"mutation_names": NAMES}, store.emitter[:n])


def _relative(c: NDArray) -> NDArray:
    """Colour scaled to luminance 1 (zeros stay zero)."""
    y = luminance(c)
    return np.where(y[:, None] > 0, c / np.where(y > 0, y, 1.0)[:, None], 0.0)


def _pixel(window, raster: NDArray) -> NDArray:
    return window.pixel(raster, clip=True)[0]
