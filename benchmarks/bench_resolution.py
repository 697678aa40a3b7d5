"""Resolution sweep (issue 17): ERCUTS, BDPT, PATH and Cycles at the resolutions users render at.

    .venv/bin/python benchmarks/bench_resolution.py --dry-run      # the plan and its time
    .venv/bin/python benchmarks/bench_resolution.py                # render what is missing, write the report
    .venv/bin/python benchmarks/bench_resolution.py --report-only

Every indirect scene at 160×120, 640×480, 1280×720 and 1920×1080 with a budget that grows with
the pixels (30 s, 2, 5 and 10 min by default), each engine at its defaults with
``time_limit`` = budget (Cycles: the matched unbiased settings of :mod:`cycles_runner`). Each
render runs in its own process, which reports its peak resident memory (``ru_maxrss``) and,
for ERCUTS, the time of every phase. Errors are measured on the image box-filtered down to
the reference's resolution — 160×120 for the 4:3 sizes, 160×90 for the 16:9 ones (1280×720
and 1920×1080 are 8× and 12× that) — against the converged 63-bounce Cycles reference of
``make_references.py`` at that size (a full-resolution reference at 1080p would take days
on this machine): this measures the error a viewer sees at the reference's scale, and the
high-frequency noise that averages away inside a block is not counted (it is for every
engine alike). Writes ``results/resolution.md``, ``resolution.json``,
``resolution_error.png`` (error against resolution) and ``resolution_phases.png``
(ERCUTS's phases' share of the time). Runs are stored in ``results/resolution_runs/`` and
skipped when present (resumable).
"""
from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
sys.path[:0] = [ROOT, HERE]

import metrics  # noqa: E402

RESULTS = os.path.join(HERE, "results")
RUNS = os.path.join(RESULTS, "resolution_runs")
SIZES = ((160, 120), (640, 480), (1280, 720), (1920, 1080))
BUDGETS = {(160, 120): 30.0, (640, 480): 120.0, (1280, 720): 300.0, (1920, 1080): 600.0}
ENGINES = ("ERCUTS", "BDPT", "PATH", "CYCLES")
SCENES = ("s_corridor", "door_ajar", "baffled_lamp", "veach_room", "mirror_glass_room")
#: Targets: ERCUTS ≤ 0.25× Cycles' relMSE at 1280×720 in 5 min and ≤ 0.5× at 1920×1080 in
#: 10 min; peak memory at 1080p under 4 GiB with the defaults.
TARGETS = {(1280, 720): 0.25, (1920, 1080): 0.5}
MEMORY_TARGET_MB = 4096
PHASES = ("bdpt", "direct", "seeds", "chains", "vpls", "tree", "cuts")


def reference_size(w: int, h: int) -> tuple[int, int]:
    """The reference resolution a (w, h) render is compared at: 160 wide, same aspect."""
    return 160, int(round(160 * h / w))


def run_base(scene: str, engine: str, w: int, h: int, budget: float, seed: int) -> str:
    return os.path.join(RUNS, scene, f"{engine}_{w}x{h}_{budget:g}s_seed{seed}")


# --------------------------------------------------------------------------- one render (child)

def render_child(scene: str, engine: str, w: int, h: int, budget: float, seed: int, base: str) -> None:
    """Render one cell in this process and store its box-filtered image and record."""
    t0 = time.perf_counter()
    record = dict(scene=scene, engine=engine, width=w, height=h, budget=budget, seed=seed)
    if engine == "CYCLES":
        import cycles_runner

        rate = cycles_runner.calibrate(scene, w, h, samples=16)  # 4 left start-up in the rate
        r = cycles_runner.render_cycles(scene, budget, seed, w, h, rate)
        image = r.pop("image")
        record.update(samples=r["samples"], capped=r["capped"], settings=r["settings"])
    else:
        from ercuts_core import RenderSettings, render
        from ercuts_core.scenes import SCENES as BUILTIN

        settings = RenderSettings(integrator=engine, seed=seed, time_limit=budget)
        result = render(BUILTIN[scene](w, h), settings)
        image = result.image[..., :3]
        record.update(stats={k: v for k, v in result.stats.items() if isinstance(v, (int, float, str))},
                      timings=result.timings, stopped_by=result.stopped_by)
    record["wall"] = time.perf_counter() - t0
    record["peak_rss_mb"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    rw, rh = reference_size(w, h)
    small = box_filter(np.asarray(image, np.float64), rw, rh)
    os.makedirs(os.path.dirname(base), exist_ok=True)
    np.savez_compressed(base + ".npz", image=small.astype(np.float32))
    with open(base + ".json", "w") as fh:
        json.dump(record, fh, indent=1)


def box_filter(img: np.ndarray, w: int, h: int) -> np.ndarray:
    """(H, W, 3) → (h, w, 3) by averaging (H/h)×(W/w) blocks (integer factors)."""
    H, W = img.shape[:2]
    fy, fx = H // h, W // w
    assert fy * h == H and fx * w == W, (img.shape, w, h)
    return img.reshape(h, fy, w, fx, 3).mean(axis=(1, 3))


# --------------------------------------------------------------------------- driver

def plan(args) -> list[tuple]:
    return [(s, e, w, h, BUDGETS[(w, h)] * args.budget_scale, k) for (w, h) in args.sizes
            for s in args.scenes for k in range(args.seeds) for e in args.engines]


def run_all(args) -> int:
    jobs = [j for j in plan(args) if not os.path.exists(run_base(*j) + ".json")]
    print(f"bench_resolution: {len(jobs)} renders to do ≈ {sum(j[4] + 10 for j in jobs) / 60:.0f} min",
          flush=True)
    if args.dry_run:
        return 0
    failures = 0
    for i, (s, e, w, h, b, k) in enumerate(jobs):
        base = run_base(s, e, w, h, b, k)
        cmd = [sys.executable, os.path.abspath(__file__), "--child", s, e, str(w), str(h), str(b), str(k), base]
        t0 = time.perf_counter()
        proc = subprocess.run(cmd, capture_output=True, text=True)
        if proc.returncode != 0:
            failures += 1
            os.makedirs(os.path.dirname(base), exist_ok=True)
            with open(base + ".json", "w") as fh:
                json.dump(dict(scene=s, engine=e, width=w, height=h, budget=b, seed=k,
                               error=proc.stderr[-2000:]), fh, indent=1)
        print(f"bench_resolution: [{i + 1}/{len(jobs)}] {s} {e} {w}x{h} {b:g} s: "
              f"{'FAILED' if proc.returncode else 'ok'} in {time.perf_counter() - t0:.0f} s", flush=True)
    return failures


# --------------------------------------------------------------------------- report

def load_runs() -> list[dict]:
    out = []
    for scene in sorted(os.listdir(RUNS)) if os.path.isdir(RUNS) else []:
        d = os.path.join(RUNS, scene)
        for f in sorted(os.listdir(d)):
            if f.endswith(".json"):
                with open(os.path.join(d, f)) as fh:
                    rec = json.load(fh)
                if "error" not in rec:
                    rec["image"] = np.load(os.path.join(d, f[:-5] + ".npz"))["image"].astype(np.float64)
                out.append(rec)
    return out


def reference(scene: str, w: int, h: int):
    """The stored Cycles reference at (w, h) (:func:`report.load_reference`), or None."""
    from report import load_reference

    ref = load_reference(scene, w, h)
    return None if ref is None else dict(image=ref["image"], floor=ref["floor"]["relmse"])


def evaluate(runs: list[dict]) -> None:
    refs: dict = {}
    for r in runs:
        if "image" not in r:
            continue
        key = (r["scene"], *reference_size(r["width"], r["height"]))
        if key not in refs:
            refs[key] = reference(*key)
        ref = refs[key]
        if ref is None:
            continue
        r["relmse"] = metrics.relmse(r["image"], ref["image"])
        r["relmse_corr"] = r["relmse"] - ref["floor"]
        r["energy"] = metrics.energy_ratio(r["image"], ref["image"])


def _cell(rs, key, fmt="{:.4f}"):
    v = [r[key] for r in rs if key in r]
    return fmt.format(float(np.median(v))) if v else "–"


def write_report(args) -> str:
    runs = load_runs()
    evaluate(runs)
    lines = ["# Resolution sweep (issue 17)", "",
             "Generated by `benchmarks/bench_resolution.py`; errors of the image box-filtered to 160 "
             "pixels wide (160×120 or 160×90) against the 63-bounce Cycles reference at that size, "
             "floor-corrected (the reference's own expected relMSE subtracted); medians over seeds; "
             "peak memory = the render process's maximum resident set.", "",
             "| scene | resolution | budget | ERCUTS | BDPT | PATH | Cycles | ERCUTS / Cycles | target "
             "| ERCUTS energy | ERCUTS iterations | peak MiB (ERCUTS / BDPT / PATH / Cycles) |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    table = {}
    for (w, h) in args.sizes:
        for s in args.scenes:
            cells = {e: [r for r in runs if (r["scene"], r["engine"], r["width"], r["height"]) == (s, e, w, h)
                         and "relmse" in r] for e in args.engines}
            if not cells.get("ERCUTS"):
                continue
            er, cy = cells["ERCUTS"], cells.get("CYCLES") or []
            ratio = (np.median([r["relmse_corr"] for r in er]) / np.median([r["relmse_corr"] for r in cy])
                     if cy and np.median([r["relmse_corr"] for r in cy]) > 0 else None)
            target = TARGETS.get((w, h))
            verdict = "–" if target is None or ratio is None else (
                f"≤ {target}: {'met' if ratio <= target else '**missed**'}")
            mem = " / ".join(_cell(cells.get(e) or [], "peak_rss_mb", "{:.0f}") for e in ENGINES)
            its = f"{np.median([r['stats'].get('iterations', 1) for r in er]):.0f}"
            lines.append(f"| {s} | {w}×{h} | {er[0]['budget']:g} s | " +
                         " | ".join(_cell(cells.get(e) or [], "relmse_corr") for e in ENGINES) +
                         f" | {'–' if ratio is None else f'{ratio:.2f}'} | {verdict} | {_cell(er, 'energy', '{:.3f}')} "
                         f"| {its} | {mem} |")
            table[f"{s}_{w}x{h}"] = dict(ratio=ratio, **{e: [r.get("relmse_corr") for r in (cells.get(e) or [])]
                                                         for e in ENGINES})
    mem_1080 = [r["peak_rss_mb"] for r in runs if r["engine"] == "ERCUTS" and r["width"] == 1920 and "peak_rss_mb" in r]
    if mem_1080:
        lines += ["", f"ERCUTS peak memory at 1920×1080 with the defaults: {max(mem_1080):.0f} MiB (target < "
                  f"{MEMORY_TARGET_MB} MiB: {'met' if max(mem_1080) < MEMORY_TARGET_MB else '**missed**'})."]
    lines += ["", "![error against resolution](resolution_error.png)", "",
              "![ERCUTS phases' share of the time](resolution_phases.png)", ""]
    plot(runs, args)
    out = os.path.join(RESULTS, "resolution.md")
    with open(out, "w") as fh:
        fh.write("\n".join(lines) + "\n")
    with open(os.path.join(RESULTS, "resolution.json"), "w") as fh:
        json.dump(table, fh, indent=1)
    return out


def plot(runs, args) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(args.scenes), figsize=(4 * len(args.scenes), 3.4), squeeze=False)
    for ax, s in zip(axes[0], args.scenes):
        for e in args.engines:
            pts = [(w * h, np.median([r["relmse_corr"] for r in runs if (r["scene"], r["engine"], r["width"],
                                      r["height"]) == (s, e, w, h) and "relmse" in r] or [np.nan]))
                   for (w, h) in args.sizes]
            ax.plot([p[0] for p in pts], [max(p[1], 1e-6) for p in pts], marker="o", label=e)
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("pixels (budget grows with them)")
        ax.set_title(s)
        ax.grid(True, which="both", alpha=0.3)
    axes[0][0].set_ylabel("relMSE (box-filtered, floor-corrected)")
    axes[0][0].legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(os.path.join(RESULTS, "resolution_error.png"), dpi=100)
    plt.close(fig)
    fig, ax = plt.subplots(figsize=(6, 3.4))
    labels, bottoms = [], None
    er = [[r for r in runs if r["engine"] == "ERCUTS" and (r["width"], r["height"]) == sz and "timings" in r]
          for sz in args.sizes]
    shares = np.array([[np.median([r["timings"].get(p, 0.0) / max(r["timings"].get("total", 1.0), 1e-9)
                                   for r in rs]) if rs else 0.0 for p in PHASES] for rs in er])
    bottoms = np.zeros(len(args.sizes))
    for j, p in enumerate(PHASES):
        ax.bar(range(len(args.sizes)), shares[:, j], bottom=bottoms, label=p)
        bottoms += shares[:, j]
    labels = [f"{w}×{h}" for w, h in args.sizes]
    ax.set_xticks(range(len(args.sizes)), labels)
    ax.set_ylabel("share of the render time")
    ax.legend(fontsize=7, ncol=4)
    fig.tight_layout()
    fig.savefig(os.path.join(RESULTS, "resolution_phases.png"), dpi=100)
    plt.close(fig)


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if argv and argv[0] == "--child":
        s, e, w, h, b, k, base = argv[1:8]
        render_child(s, e, int(w), int(h), float(b), int(k), base)
        return 0
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", nargs="+", default=list(SCENES[:2]), choices=SCENES)
    ap.add_argument("--engines", nargs="+", default=list(ENGINES), choices=ENGINES)
    ap.add_argument("--sizes", nargs="+", default=[f"{w}x{h}" for w, h in SIZES])
    ap.add_argument("--seeds", type=int, default=1)
    ap.add_argument("--budget-scale", type=float, default=1.0, help="multiply every budget (quick checks)")
    ap.add_argument("--report-only", action="store_true")
    ap.add_argument("--dry-run", action="store_true")
    args = ap.parse_args(argv)
    args.sizes = [tuple(int(x) for x in sz.split("x")) for sz in args.sizes]
    failures = 0 if args.report_only else run_all(args)
    if not args.dry_run:
        print(f"bench_resolution: wrote {write_report(args)}")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
