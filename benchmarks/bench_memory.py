"""Peak memory of ERCUTS renders at 160×120, 640×480 and 1920×1080 (issue #6, memory).

Each case runs in its own subprocess (a fresh interpreter, so peaks do not carry over) and
reports the process's peak resident set size (``VmHWM`` from /proc/self/status), the RSS
before rendering (interpreter + numpy + embree + the scene description), and the core's
own estimate (:mod:`ercuts_core.memory`, ``stats['memory_estimate_mb']``). Settings are
the defaults (memory budget 4096 MiB) except for the few that keep a case short with
every phase running (BDPT, seeds, chains, VPLs, tree, lightcuts). At 1080p the first
rough BDPT pass and the seed paths alone take minutes on 2 busy cores and a time limit
cannot shorten them (a limit that ran out there would skip the later phases), so the
1080p case runs without a limit (about 15 minutes). A last case asks for 1080p with a
1024 MiB budget and shows the error.

Usage: ``.venv/bin/python benchmarks/bench_memory.py`` → benchmarks/results/memory.md + .json
"""
from __future__ import annotations

import json
import pathlib
import subprocess
import sys
import time

ROOT = pathlib.Path(__file__).resolve().parents[1]
OUT = ROOT / "benchmarks" / "results"
SIZES = [(160, 120), (640, 480), (1920, 1080)]
#: Fast settings: one rough BDPT pass and one direct-light pass, short chains, few E1 samples;
#: the time limit caps the gather.
FAST = dict(samples=1, direct_samples=1, max_depth=2, chain_length=10, e1_samples=16, max_cut_size=100)
#: Time limits by width (0 = none): long enough for the first BDPT pass and the seed paths
#: (which a limit cannot shorten); the later phases share the rest and the gather fits its
#: cut size. 1080p runs without a limit: its first pass and seeds take over 10 minutes.
TIME_LIMIT = {160: 60.0, 640: 120.0, 1920: 0.0}
PHASES = ("bdpt", "direct", "seeds", "chains", "vpls", "tree", "cuts")

CHILD = r"""
import json, sys, time
sys.path.insert(0, {root!r})
from ercuts_core import RenderSettings, render, scenes
from ercuts_core.memory import MemoryBudgetError

def status(key):
    for line in open("/proc/self/status"):
        if line.startswith(key + ":"):
            return int(line.split()[1]) / 1024.0      # kB -> MiB
w, h, kw = {w}, {h}, {kw!r}
desc = scenes.s_corridor(w, h)
base = status("VmRSS")
t0 = time.perf_counter()
out = dict(width=w, height=h, settings=kw, baseline_mb=base)
try:
    r = render(desc, RenderSettings(**kw))
    out.update(wall_s=time.perf_counter() - t0, peak_rss_mb=status("VmHWM"),
               estimate_mb=r.stats["memory_estimate_mb"], cancelled=r.cancelled,
               timings=r.timings, stats={{k: r.stats.get(k) for k in
                   ("bdpt_samples", "seed_paths", "chains", "chain_steps", "vpls", "cut_size_mean",
                    "gather_incomplete", "nonfinite_samples")}})
except MemoryBudgetError as exc:
    out.update(error=str(exc), wall_s=time.perf_counter() - t0, peak_rss_mb=status("VmHWM"))
print("RESULT " + json.dumps(out))
"""


def run_case(w: int, h: int, kw: dict) -> dict:
    code = CHILD.format(root=str(ROOT), w=w, h=h, kw=kw)
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT)
    line = [x for x in proc.stdout.splitlines() if x.startswith("RESULT ")]
    if proc.returncode or not line:
        raise RuntimeError(f"case {w}x{h} failed:\n{proc.stderr[-3000:]}")
    return json.loads(line[-1][7:])


def report(cases: list[dict]) -> str:
    rows = ["| resolution | peak RSS (MiB) | RSS before render | render's own peak | estimate (MiB) "
            "| wall (s) | VPLs | chains × steps | phases run |",
            "|---|---|---|---|---|---|---|---|---|"]
    for c in cases:
        if "error" in c:
            continue
        ran = [p for p in PHASES if p in c["timings"]]
        st = c["stats"]
        rows.append(f"| {c['width']}×{c['height']} | {c['peak_rss_mb']:.0f} | {c['baseline_mb']:.0f} | "
                    f"{c['peak_rss_mb'] - c['baseline_mb']:.0f} | {c['estimate_mb']:.0f} | {c['wall_s']:.0f} | "
                    f"{st['vpls']} | {st['chains']} × {st['chain_steps']} | {len(ran)}/{len(PHASES)} |")
    errors = [c for c in cases if "error" in c]
    text = ["# Peak memory of ERCUTS renders (`benchmarks/bench_memory.py`)", "",
            f"S-corridor, default settings and memory budget (4096 MiB) except {FAST} and time "
            f"limits {TIME_LIMIT} s by width (one rough BDPT pass, short paths and chains, small "
            "cuts, so that every phase runs on 2 busy cores). Peak RSS is `VmHWM` of a fresh process per "
            "case; 'RSS before render' is the interpreter, numpy, embree and the description.", "",
            *rows, ""]
    for c in errors:
        text += [f"With `memory_budget_mb={c['settings'].get('memory_budget_mb', 4096)}` at {c['width']}×{c['height']} the "
                 f"render is refused before allocating ({c['wall_s']:.2f} s, peak RSS {c['peak_rss_mb']:.0f} MiB):", "",
                 f"> {c['error']}", ""]
    return "\n".join(text)


def main() -> None:
    OUT.mkdir(parents=True, exist_ok=True)
    cases = []
    for w, h in SIZES:
        t = time.perf_counter()
        cases.append(run_case(w, h, dict(FAST, time_limit=TIME_LIMIT[w])))
        print(f"{w}x{h}: peak {cases[-1]['peak_rss_mb']:.0f} MiB in {time.perf_counter() - t:.0f} s", flush=True)
    cases.append(run_case(1920, 1080, dict(FAST, memory_budget_mb=1024)))
    (OUT / "memory.json").write_text(json.dumps(cases, indent=1))
    (OUT / "memory.md").write_text(report(cases))
    print(report(cases))


if __name__ == "__main__":
    main()
