"""Does a code change keep every image bit for bit? Renders a fixed set of cases (fixed seed,
no time limit) with this checkout and with another revision and compares the arrays.

    .venv/bin/python benchmarks/same_image.py --base b293965          # compare with a revision
    .venv/bin/python benchmarks/same_image.py --save out/images.npz   # just render and store

The base revision is checked out into a temporary ``git worktree`` and rendered there in a
subprocess (the same Python), so both sides run the same cases in the same environment.
Compared: the image, every AOV and the numeric statistics that do not measure time. Exit
status 1 when any array differs (the report names the first differing case and array).
"""
from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile

import numpy as np

#: (name, built-in scene, scene kwargs, settings): the S-corridor and Cornell box at the
#: defaults (the refactor issue's acceptance cases), plus the ablations and the other
#: integrators at smaller sizes so that every code path is covered.
CASES = [
    ("s_corridor_ercuts", "s_corridor", {}, {}),
    ("cornell_box_ercuts", "cornell_box", {}, {}),
    ("cornell_box_vpl", "cornell_box", {"width": 64, "height": 48}, {"direct_light": "VPL"}),
    ("s_corridor_brute", "s_corridor", {"width": 48, "height": 36}, {"gather": "BRUTE_FORCE"}),
    ("cornell_box_bdpt", "cornell_box", {"width": 64, "height": 48}, {"integrator": "BDPT", "samples": 4}),
    ("s_corridor_path", "s_corridor", {"width": 64, "height": 48}, {"integrator": "PATH", "samples": 4}),
    # point and spot lights (delta: radius 0) through every integrator
    ("point_lit_box_ercuts", "point_lit_box", {"width": 32, "height": 24}, {}),
    ("point_lit_box_bdpt", "point_lit_box", {"width": 32, "height": 24}, {"integrator": "BDPT", "samples": 4}),
]
#: Statistics that measure time or memory (never compared).
TIMED = ("memory_estimate_mb",)


def render_cases(root: str) -> dict[str, np.ndarray]:
    """Render :data:`CASES` with the ``ercuts_core`` found under ``root``; flat name → array."""
    sys.path.insert(0, root)
    from ercuts_core import RenderSettings, render
    from ercuts_core.scenes import SCENES

    out = {}
    for name, scene, kwargs, settings in CASES:
        res = render(SCENES[scene](**kwargs), RenderSettings(**settings))
        out[f"{name}/image"] = res.image
        for key, value in sorted(res.aovs.items()):
            out[f"{name}/aov/{key}"] = np.asarray(value)
        stats = {k: v for k, v in res.stats.items()
                 if isinstance(v, (int, float)) and k not in TIMED}
        out[f"{name}/stats_keys"] = np.array(sorted(stats))
        out[f"{name}/stats"] = np.array([float(stats[k]) for k in sorted(stats)])
        print(f"{name}: rendered, {res.timings.get('total', 0):.1f} s", file=sys.stderr)
    return out


def base_images(rev: str, root: str) -> dict[str, np.ndarray]:
    """Render :data:`CASES` at git revision ``rev`` (a temporary worktree)."""
    with tempfile.TemporaryDirectory() as tmp:
        tree = os.path.join(tmp, "base")
        subprocess.run(["git", "-C", root, "worktree", "add", "--detach", tree, rev], check=True,
                       capture_output=True)
        try:
            path = os.path.join(tmp, "base.npz")
            me = os.path.abspath(__file__)
            subprocess.run([sys.executable, me, "--root", tree, "--save", path], check=True)
            with np.load(path) as data:
                return dict(data)
        finally:
            subprocess.run(["git", "-C", root, "worktree", "remove", "--force", tree], check=False)


def stats_changes(base: dict, new: dict) -> tuple[list[str], list[str]]:
    """(statistics whose values differ, statistics present on one side only), as
    ``case/name``; statistics are compared by name, so an added or removed one is reported
    on its own and does not hide the others."""
    differ, one_side = [], []
    for key in sorted(k for k in set(base) | set(new) if k.endswith("/stats")):
        case = key[: -len("/stats")]
        a = dict(zip(base.get(f"{case}/stats_keys", []), base.get(key, [])))
        b = dict(zip(new.get(f"{case}/stats_keys", []), new.get(key, [])))
        one_side += [f"{case}/{k}" for k in sorted(set(a) ^ set(b))]
        differ += [f"{case}/{k}" for k in sorted(set(a) & set(b))
                   if not np.array_equal(a[k], b[k], equal_nan=True)]
    return differ, one_side


def compare(base: dict, new: dict) -> list[str]:
    """Names of the images and AOVs that are not bit-identical (missing on either side
    included); statistics: :func:`stats_changes`."""
    bad = []
    for key in sorted(k for k in set(base) | set(new) if "/stats" not in k):
        a, b = base.get(key), new.get(key)
        if a is None or b is None or a.shape != b.shape or a.dtype != b.dtype \
                or not np.array_equal(a, b, equal_nan=a.dtype.kind == "f"):
            bad.append(key)
    return bad


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--base", help="git revision to compare with")
    ap.add_argument("--save", help="write this checkout's arrays to this .npz")
    ap.add_argument("--root", default=os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    args = ap.parse_args(argv)
    new = render_cases(args.root)
    if args.save:
        np.savez(args.save, **new)
    if not args.base:
        return 0
    base = base_images(args.base, args.root)
    bad = compare(base, new)
    differ, one_side = stats_changes(base, new)
    n_arrays = sum("/stats" not in k for k in new)
    if one_side:
        print(f"statistics on one side only (added or removed): {one_side}")
    if bad or differ:
        print(f"DIFFERENT: {len(bad)} images/AOVs differ, first: {bad[:5]}; "
              f"{len(differ)} statistics differ, first: {differ[:5]}")
        return 1
    print(f"identical: {n_arrays} images and AOVs of {len(CASES)} cases bit for bit, and every "
          f"statistic both sides have (base {args.base})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
