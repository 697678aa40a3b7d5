"""Converged Cycles references for the benchmark scenes, stored with the scenes.

    nice -n 19 .venv/bin/python benchmarks/make_references.py                 # all scenes
    nice -n 19 .venv/bin/python benchmarks/make_references.py --until 08:45 --rounds 12

Cycles (the bpy module, CPU, settings of :mod:`cycles_runner`: unbiased, the files' path
length) renders each scene in independent chunks of ``CHUNK_SPP`` samples with different
seeds, round-robin over the scenes so that every scene has a usable reference early. The
running sums live in ``out/references_work/``, so the script resumes where it stopped.
After every round it writes, atomically,

* ``blend_scenes/references/<scene>_<W>x<H>.exr``: RGBA = the mean of the chunks; channels
  ``var.R/G/B`` = the per-pixel variance of that mean (chunk-to-chunk variance / chunks);
* ``blend_scenes/references/<scene>_<W>x<H>.json``: spp, chunks, render time, Cycles
  settings, and the reference's own noise: the relMSE (ε = 0.01) that the reference adds
  in expectation to any image compared with it, mean(var / (ref² + ε)), and the relMSE
  between the means of the first and second half of the chunks.
"""
from __future__ import annotations

import argparse
import datetime as dt
import json
import os
import sys

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
sys.path[:0] = [ROOT, HERE]

import cycles_runner  # noqa: E402
from ercuts_core.image_io import atomic_path, write_exr  # noqa: E402
from ercuts_core.settings import quick  # noqa: E402
from metrics import EPS, relmse  # noqa: E402

REF_DIR = os.path.join(ROOT, "blend_scenes", "references")
WORK = os.path.join(ROOT, "out", "references_work")
#: Cycles samples per chunk (about a minute each on 2 cores).
CHUNK_SPP = {"s_corridor": 2048, "cornell_box": 2048, "door_ajar": 1024, "baffled_lamp": 1024,
             "directly_lit": 2048, "textured_living_room": 1024, "textured_bedroom": 1024,
             "veach_room": 1024, "mirror_glass_room": 1024}
#: ``ERCUTS_QUICK=1`` (README): a smoke run — at most QUICK_ROUNDS chunks of QUICK_SPP samples
#: per scene, written to ``out/quick/references/`` (never over the stored references).
QUICK = quick()
QUICK_ROUNDS, QUICK_SPP = 2, 4


def ref_paths(name: str, width: int = 160, height: int = 120) -> tuple[str, str]:
    base = os.path.join(REF_DIR, f"{name}_{width}x{height}")
    return base + ".exr", base + ".json"


def _state(name, w, h):
    path = os.path.join(WORK, f"{name}_{w}x{h}.npz")
    if os.path.exists(path):
        z = np.load(path)
        return path, {k: z[k] for k in z.files}
    return path, dict(chunks=np.zeros((0, h, w, 3), np.float32), seconds=np.zeros(0))


def _save_state(path, st):
    with atomic_path(path, ".npz") as tmp:
        np.savez(tmp, **st)


def write_reference(name: str, w: int, h: int, st: dict, settings: dict) -> dict:
    chunks = st["chunks"].astype(np.float64)
    k = len(chunks)
    mean = chunks.mean(0)
    var = chunks.var(0, ddof=1) / k if k > 1 else np.full_like(mean, np.nan)
    half = k // 2
    info = dict(scene=name, width=w, height=h, renderer="Cycles (bpy module, CPU)",
                spp=int(k * CHUNK_SPP[name]), chunks=k, chunk_spp=CHUNK_SPP[name],
                render_seconds=float(st["seconds"].sum()), settings=settings,
                expected_relmse_of_reference=float(np.mean(var / (mean**2 + EPS))) if k > 1 else None,
                relmse_between_halves=(relmse(chunks[:half].mean(0), chunks[half:].mean(0))
                                       if k > 1 else None),
                written=dt.datetime.now(dt.timezone.utc).isoformat(timespec="seconds"))
    exr, js = ref_paths(name, w, h)
    os.makedirs(REF_DIR, exist_ok=True)
    rgba = np.concatenate([mean, np.ones(mean.shape[:2] + (1,))], axis=2)
    write_exr(exr, rgba, {"var": np.nan_to_num(var)})
    with atomic_path(js, ".json") as tmp, open(tmp, "w") as fh:
        json.dump(info, fh, indent=1)
    return info


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", nargs="*", default=list(CHUNK_SPP))
    ap.add_argument("--rounds", type=int, default=16, help="chunks per scene at most")
    ap.add_argument("--until", help="stop starting chunks after this UTC time (HH:MM)")
    ap.add_argument("--width", type=int, default=160)
    ap.add_argument("--height", type=int, default=120)
    args = ap.parse_args(argv)
    if QUICK:
        global REF_DIR, WORK
        REF_DIR = os.path.join(ROOT, "out", "quick", "references")
        WORK = os.path.join(REF_DIR, "work")
        CHUNK_SPP.update((name, QUICK_SPP) for name in CHUNK_SPP)
        args.rounds = min(args.rounds, QUICK_ROUNDS)
        print(f"make_references: ERCUTS_QUICK: {args.rounds} chunks of {QUICK_SPP} spp per scene, "
              f"written to {REF_DIR}", flush=True)
    os.makedirs(WORK, exist_ok=True)
    stop = None
    if args.until:
        hh, mm = map(int, args.until.split(":"))
        now = dt.datetime.now(dt.timezone.utc)
        stop = now.replace(hour=hh, minute=mm, second=0, microsecond=0)
    for rnd in range(args.rounds):
        for name in args.scenes:
            if stop and dt.datetime.now(dt.timezone.utc) >= stop:
                print("make_references: stop time reached", flush=True)
                return 0
            path, st = _state(name, args.width, args.height)
            if len(st["chunks"]) > rnd:
                continue
            r = cycles_runner.render_fixed(name, CHUNK_SPP[name], 1000 + rnd, args.width, args.height)
            st["chunks"] = np.concatenate([st["chunks"], r["image"][None].astype(np.float32)])
            st["seconds"] = np.append(st["seconds"], r["times"].get("render_time", r["wall"]))
            _save_state(path, st)
            info = write_reference(name, args.width, args.height, st, r["settings"])
            print(f"make_references: {name} chunk {rnd + 1}: {r['wall']:.0f} s, {info['spp']} spp, "
                  f"reference relMSE {info['expected_relmse_of_reference']}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
