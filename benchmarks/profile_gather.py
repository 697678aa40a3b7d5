"""Where an ERCUTS iteration spends its time at production resolution, and inside the gather.

Two steps (issue 17: "profile at 1280×720 first"):

``--capture``: renders the builtin S-corridor at ``--size`` (default 1280×720) with one
iteration and ``--time-limit`` seconds (the gather is paced to fit), under cProfile; prints
the time per phase (``result.timings``) and the top functions, and pickles the gather's
inputs (G-buffer, VPLs, light tree, clamp, P) to ``out/gather_state_<w>x<h>.pkl``.

``--gather``: loads that state and runs the gather, unpaced, on ``--points`` shading points
(a shuffled sample, as the gather visits them) for each ``--modes`` (LIGHTCUTS, STOCHASTIC),
A/B interleaved ``--repeats`` times for each kernel backend (``numba`` and ``numpy``, see
:mod:`ercuts_core.kernels`); prints the time per shading point and under cProfile the share
spent in embreex (``Tracer.occluded``) against the numpy/Python bookkeeping around it.

Run::

    nice -n 5 .venv/bin/python benchmarks/profile_gather.py --capture --time-limit 240
    nice -n 5 .venv/bin/python benchmarks/profile_gather.py --gather --points 20000

Writes ``benchmarks/results/profile_gather.md`` (appends a section per run). The machine is
shared: compare the interleaved backends, not seconds across runs.
"""
from __future__ import annotations

import argparse
import cProfile
import io
import os
import pickle
import pstats
import sys
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

from ercuts_core import RenderSettings, render, scenes  # noqa: E402
from ercuts_core import kernels  # noqa: E402
from ercuts_core.integrators.ercuts import gather as gather_mod  # noqa: E402
from ercuts_core.integrators.ercuts.pacing import Schedule  # noqa: E402
from ercuts_core.integrators.base import Clock  # noqa: E402
from ercuts_core.scene import BuiltScene  # noqa: E402
from ercuts_core.validate import sanitize  # noqa: E402

OUT = os.path.join(ROOT, "benchmarks", "results", "profile_gather.md")


def state_path(w: int, h: int) -> str:
    return os.path.join(ROOT, "out", f"gather_state_{w}x{h}.pkl")


def _top(pr: cProfile.Profile, n: int = 25) -> tuple[str, pstats.Stats]:
    buf = io.StringIO()
    st = pstats.Stats(pr, stream=buf)
    st.sort_stats("tottime").print_stats(n)
    return buf.getvalue(), st


def _cum(st: pstats.Stats, file_end: str, name: str) -> float:
    return sum(v[3] for k, v in st.stats.items() if k[2] == name and k[0].endswith(file_end))


def capture(w: int, h: int, time_limit: float, gather: str) -> list[str]:
    """One paced iteration under cProfile; pickles the gather's inputs."""
    desc = scenes.s_corridor(w, h)
    saved = {}
    orig = gather_mod.Gather.run

    def run(self, vpls, tree, gmax, schedule, stats, show):
        saved.update(g=self.g, vpls=vpls, tree=tree, gmax=gmax, P=stats.get("P", 0.0),
                     batch=self.gather_batch)
        return orig(self, vpls, tree, gmax, schedule, stats, show)

    gather_mod.Gather.run = run
    settings = RenderSettings(time_limit=time_limit, seed=0, gather=gather, iterations=1)
    pr = cProfile.Profile()
    t0 = time.perf_counter()
    pr.enable()
    try:
        res = render(desc, settings)
    finally:
        pr.disable()
        gather_mod.Gather.run = orig
    wall = time.perf_counter() - t0
    os.makedirs(os.path.dirname(state_path(w, h)), exist_ok=True)
    if saved:
        with open(state_path(w, h), "wb") as fh:
            pickle.dump(saved, fh)
    text, st = _top(pr)
    occl = _cum(st, "tracer.py", "occluded")
    isect = _cum(st, "tracer.py", "intersect")
    lines = [f"## capture {w}×{h}, gather={gather}, time_limit={time_limit:g} s "
             f"({time.strftime('%Y-%m-%d %H:%M')}, load {os.getloadavg()[0]:.1f})", "",
             f"wall {wall:.1f} s (under cProfile); phases (s): " + ", ".join(
                 f"{k} {v:.1f}" for k, v in res.timings.items()), "",
             f"Tracer.occluded {occl:.1f} s, Tracer.intersect {isect:.1f} s (cumulative, whole render); "
             f"cut mean {res.stats.get('cut_size_mean', 0):.1f}, VPLs {res.stats.get('vpls', 0)}, "
             f"paced error {res.stats.get('max_error_for_time_limit', '-')}, "
             f"cut cap {res.stats.get('cut_cap_for_time_limit', '-')}, "
             f"passes {res.stats.get('gather_passes', 1)}", "", "```", text.strip()[:6000], "```", ""]
    return lines


def _gather_once(state, scene, mode: str, pts: np.ndarray, seed: int, sharing: int = 1):
    s = RenderSettings(gather=mode, seed=seed, stochastic_cut_sharing=sharing)
    g = state["g"]
    ga = gather_mod.Gather(scene, s, g, state["batch"])
    sched = Schedule(Clock(0.0, None, None), direct_vpls=False, paced=False)
    stats = {"P": state["P"]}
    sweep = gather_mod._Sweep(ga, state["vpls"], state["tree"], state["gmax"], sched, stats, pts)
    Q = len(g.pixel)
    L = np.zeros((2, Q, 3))
    cut = np.zeros(Q)
    step = gather_mod.PROGRESS_GATHER_POINTS
    t0 = time.perf_counter()
    for start in range(0, len(pts), step):
        sweep._batch(pts[start:start + step], start, 0, L, cut)
    return time.perf_counter() - t0, L, cut, sweep.rays


def gather_profile(w: int, h: int, n_points: int, modes: list[str], repeats: int) -> list[str]:
    with open(state_path(w, h), "rb") as fh:
        state = pickle.load(fh)
    desc = scenes.s_corridor(w, h)
    scene = BuiltScene(sanitize(desc).desc)
    g = state["g"]
    pts = gather_mod.spread_order(np.flatnonzero(g.valid), 0)[:n_points]
    lines = [f"## gather {w}×{h}: {len(pts)} shading points, {len(state['vpls'])} VPLs "
             f"({time.strftime('%Y-%m-%d %H:%M')}, load {os.getloadavg()[0]:.1f}; "
             f"numba {'available' if kernels.NUMBA else 'missing: ' + kernels.WHY_NOT})", ""]
    backends = ["numba", "numpy"] if kernels.NUMBA else ["numpy"]
    for mode in modes:
        times = {b: [] for b in backends}
        results = {}
        for _ in range(repeats):
            for b in backends:
                with kernels.backend(b):
                    _gather_once(state, scene, mode, pts[:2048], 0)      # warm-up (JIT)
                    dt, L, cut, rays = _gather_once(state, scene, mode, pts, 0)
                times[b].append(dt)
                results[b] = (L, cut, rays)
        for b in backends:
            L, cut, rays = results[b]
            best = min(times[b])
            lines.append(f"- {mode} [{b}]: best {best:.2f} s of {[round(t, 2) for t in times[b]]} → "
                         f"{1e6 * best / len(pts):.0f} µs/point, cut mean {cut[pts].mean():.1f}, "
                         f"{rays / len(pts):.1f} shadow rays/point, "
                         f"{rays / best / 1e6:.2f} Mrays/s end to end")
        if len(backends) == 2:
            a, b = results["numba"][0], results["numpy"][0]
            rel = np.abs(a - b).max() / max(np.abs(b).max(), 1e-300)
            lines.append(f"- {mode}: numba vs numpy max |ΔL| / max L = {rel:.2e}")
        for b in backends:
            pr = cProfile.Profile()
            with kernels.backend(b):
                pr.enable()
                dt, *_ = _gather_once(state, scene, mode, pts, 0)
                pr.disable()
            text, st = _top(pr, 15)
            occl = _cum(st, "tracer.py", "occluded")
            lines += [f"- {mode} [{b}] under cProfile: {dt:.2f} s, in Tracer.occluded {occl:.2f} s "
                      f"({100 * occl / dt:.0f} %), the rest numpy/Python bookkeeping", "",
                      "```", text.strip()[:4000], "```", ""]
    scene.close()
    return lines


def sharing_sweep(w: int, h: int, n_points: int, blocks: list[int], repeats: int) -> list[str]:
    """Stochastic gather with cut sharing over ``blocks``: time per point and error against
    the bounded gather (2 %, 'TOTAL', cut ≤ 1000) at the same points, interleaved."""
    with open(state_path(w, h), "rb") as fh:
        state = pickle.load(fh)
    scene = BuiltScene(sanitize(scenes.s_corridor(w, h)).desc)
    g = state["g"]
    pts = gather_mod.spread_order(np.flatnonzero(g.valid), 0)[:n_points]
    _, ref, _, _ = _gather_once(state, scene, "LIGHTCUTS", pts, 0)
    y_ref = ref.sum(axis=0)[pts] @ np.array([0.2126, 0.7152, 0.0722])
    lines = [f"## cut sharing {w}×{h}: {len(pts)} points, reference = bounded gather "
             f"({time.strftime('%Y-%m-%d %H:%M')}, load {os.getloadavg()[0]:.1f}, "
             f"backend {'numba' if kernels.enabled() else 'numpy'})", "",
             "| block | µs/point (best of runs) | relMSE vs bounded | relMSE × time |",
             "|---|---|---|---|"]
    times = {b: [] for b in blocks}
    errs = {b: [] for b in blocks}
    for r in range(repeats):
        for b in blocks:
            _gather_once(state, scene, "STOCHASTIC", pts[:1024], r, b)
            dt, L, _, _ = _gather_once(state, scene, "STOCHASTIC", pts, r, b)
            y = L.sum(axis=0)[pts] @ np.array([0.2126, 0.7152, 0.0722])
            times[b].append(dt)
            errs[b].append(float(np.sum((y - y_ref) ** 2) / np.sum(y_ref ** 2)))
    for b in blocks:
        t, e = min(times[b]), float(np.mean(errs[b]))
        lines.append(f"| {b} | {1e6 * t / len(pts):.0f} | {e:.4f} | {e * t:.4f} |")
    scene.close()
    return lines + [""]


def cancel_latency(w: int, h: int, modes: list[str], after: float = 3.0) -> list[str]:
    """Esc during the gather: the progress callback starts returning False ``after`` seconds
    into a full-image, unpaced gather pass; measured: the largest gap between progress
    calls before it, and the time from the first False to the gather's return."""
    with open(state_path(w, h), "rb") as fh:
        state = pickle.load(fh)
    scene = BuiltScene(sanitize(scenes.s_corridor(w, h)).desc)
    g = state["g"]
    lines = [f"## Esc latency {w}×{h} ({time.strftime('%Y-%m-%d %H:%M')}, load "
             f"{os.getloadavg()[0]:.1f}, backend {'numba' if kernels.enabled() else 'numpy'})", "",
             "| gather | largest gap between progress calls s | Esc → return s |", "|---|---|---|"]
    for mode in modes:
        calls, t_cancel = [], []
        t0 = time.perf_counter()

        def progress(f, msg):
            now = time.perf_counter()
            calls.append(now)
            if now - t0 > after:
                t_cancel.append(now)
                return False
            return True

        ga = gather_mod.Gather(scene, RenderSettings(gather=mode, seed=0), g, state["batch"])
        sched = Schedule(Clock(0.0, progress, None), direct_vpls=False, paced=False)
        ga.run(state["vpls"], state["tree"], state["gmax"], sched, {"P": state["P"]}, lambda *a: None)
        t_end = time.perf_counter()
        gaps = np.diff([t0] + calls)
        lines.append(f"| {mode} | {gaps.max():.2f} | {t_end - t_cancel[0]:.2f} |" if t_cancel
                     else f"| {mode} | {gaps.max():.2f} | (finished before {after} s) |")
        print(lines[-1], flush=True)
    scene.close()
    return lines + [""]


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--capture", action="store_true")
    ap.add_argument("--gather", action="store_true")
    ap.add_argument("--size", default="1280x720")
    ap.add_argument("--time-limit", type=float, default=240.0)
    ap.add_argument("--capture-gather", default="STOCHASTIC")
    ap.add_argument("--points", type=int, default=20000)
    ap.add_argument("--modes", nargs="+", default=["LIGHTCUTS", "STOCHASTIC"])
    ap.add_argument("--repeats", type=int, default=2)
    ap.add_argument("--sharing", nargs="*", type=int, help="cut-sharing blocks to sweep, e.g. 1 2 4 8")
    ap.add_argument("--cancel", action="store_true", help="Esc latency of every gather (--modes)")
    args = ap.parse_args(argv)
    w, h = (int(v) for v in args.size.split("x"))
    lines = []
    if args.capture:
        lines += capture(w, h, args.time_limit, args.capture_gather)
    if args.gather:
        lines += gather_profile(w, h, args.points, args.modes, args.repeats)
    if args.sharing:
        lines += sharing_sweep(w, h, args.points, args.sharing, args.repeats)
    if args.cancel:
        lines += cancel_latency(w, h, args.modes)
    print("\n".join(lines))
    os.makedirs(os.path.dirname(OUT), exist_ok=True)
    with open(OUT, "a") as fh:
        fh.write("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
