"""The gather's compiled kernels (``ercuts_core/kernels``, numba) against the numpy code they
replace, and the numpy fallback when numba cannot load.

Measured on this machine (numba 0.68.1): the cut refinement gives *bit-identical* cuts,
estimates and radiance to numpy in every mode (the per-point decisions and sums follow
numpy's order); the bounds differ from numpy's in the last bit for ~6 % of the pairs (the
luminance dot product, which numpy sends through BLAS), ≤ 1e-15 relative.  The tests assert
identical cuts and radiance within 1e-12 relative, and the bounds within 1e-14.
"""
from __future__ import annotations

import os
import json
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from ercuts_core import kernels
from ercuts_core.integrators.ercuts.light_tree import build_light_tree
from ercuts_core.integrators.ercuts.lightcuts import cluster_bound, lightcut
from ercuts_core.integrators.ercuts.stochastic_lightcuts import stochastic_cut, stochastic_lightcut
from tests.test_glossy_bound import glossy_points
from tests.test_rough_glass_bound import glass_points
from tests.test_lightcuts import diffuse_points, room_scene
from tests.vpl_cases import random_vpls

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def both(fn):
    """fn() with the compiled kernels and with the numpy code: (numba result, numpy result)."""
    with kernels.backend("numba"):
        a = fn()
    with kernels.backend("numpy"):
        b = fn()
    return a, b


def test_numba_loads_and_is_the_default() -> None:
    """numba is pinned (requirements.txt): the kernels are on unless ERCUTS_KERNELS=numpy."""
    assert kernels.NUMBA, kernels.WHY_NOT
    assert kernels.enabled() == (os.environ.get(kernels.ENV) != "numpy")


@pytest.mark.parametrize("kind", ["diffuse", "transmissive", "glossy", "glass"])
def test_bounds_match_numpy(kind: str) -> None:
    pos, nrm, inten = random_vpls(800, 3)
    tree = build_light_tree(pos, nrm, inten, seed=0)
    pts = (glossy_points(200, 5, diffuse_share=0.3) if kind == "glossy"
           else glass_points(200, 5, diffuse_share=0.3) if kind == "glass"
           else diffuse_points(200, 5, transmissive=kind == "transmissive"))
    rng = np.random.default_rng(1)
    node = rng.integers(0, tree.n_nodes, 40000)
    pidx = rng.integers(0, pts.count, 40000)
    for clamp in (0.0, 3.0):
        a, b = both(lambda: cluster_bound(tree, node, pts, pidx, clamp))
        assert np.array_equal(np.isinf(a), np.isinf(b)) and np.array_equal(a > 0, b > 0)
        fin = np.isfinite(b)
        np.testing.assert_allclose(a[fin], b[fin], rtol=1e-14, atol=0.0)


def _same_cut(a, b) -> None:
    assert np.array_equal(a.cut_size, b.cut_size)
    assert np.array_equal(a.cut_point, b.cut_point) and np.array_equal(a.cut_node, b.cut_node)
    assert np.array_equal(a.unmet, b.unmet)
    assert a.shadow_rays == b.shadow_rays and a.rounds == b.rounds
    np.testing.assert_allclose(a.radiance, b.radiance, rtol=1e-12, atol=0.0)
    np.testing.assert_allclose(a.cut_estimate, b.cut_estimate, rtol=1e-12, atol=0.0)
    np.testing.assert_allclose(a.clamped_energy, b.clamped_energy, rtol=1e-9, atol=1e-300)


@pytest.mark.parametrize("mode", ["total", "bound", "literal"])
@pytest.mark.parametrize("clamp", [0.0, 2.0])
def test_lightcut_matches_numpy(mode: str, clamp: float) -> None:
    """Same cuts (nodes, sizes, rounds, rays, unmet) and radiance, with the cap binding for
    part of the points and a blocker (shadow rays)."""
    lights, _ = room_scene(3000, 10, 7)
    pts = diffuse_points(400, 8, transmissive=True, occluder=True)
    tree = build_light_tree(*lights, seed=2)
    a, b = both(lambda: lightcut(tree, *lights, pts, error_mode=mode, clamp=clamp, max_cut_size=120,
                                 abs_floor=1e-6, return_cut=True))
    assert a.unmet.any() and not a.unmet.all()          # the cap binds somewhere, not everywhere
    _same_cut(a, b)


def test_lightcut_matches_numpy_at_glossy_receivers() -> None:
    pos, nrm, inten = random_vpls(1500, 4)
    tree = build_light_tree(pos, nrm, inten, seed=0)
    pts = glossy_points(150, 40, diffuse_share=0.2)
    _same_cut(*both(lambda: lightcut(tree, pos, nrm, inten, pts, error_mode="total",
                                     return_cut=True)))


def test_lightcut_matches_numpy_at_rough_glass_receivers() -> None:
    """Rough glass points (their bound by kernels.bounds.glass_bounds) with Lambert points."""
    pos, nrm, inten = random_vpls(1500, 6, scale=8.0, shift=-4.0)
    tree = build_light_tree(pos, nrm, inten, seed=0)
    pts = glass_points(150, 41, diffuse_share=0.2)
    for mode in ("total", "bound"):
        _same_cut(*both(lambda: lightcut(tree, pos, nrm, inten, pts, error_mode=mode,
                                         return_cut=True)))
    (pa, na), (pb, nb) = both(lambda: stochastic_cut(tree, pts, 32))
    assert np.array_equal(pa, pb) and np.array_equal(na, nb)


def test_lightcut_stopped_by_on_round_matches_numpy() -> None:
    """A cancel after the third round leaves the same coarser cuts on both paths."""
    lights, pts = room_scene(2000, 300, 11)
    tree = build_light_tree(*lights, seed=1)

    def run():
        calls = []
        return lightcut(tree, *lights, pts, error_mode="total", return_cut=True,
                        on_round=lambda: calls.append(1) or len(calls) < 3)
    a, b = both(run)
    assert a.rounds == 3
    _same_cut(a, b)


@pytest.mark.parametrize("cut_size", [1, 8, 32, 200])
def test_stochastic_cut_matches_numpy(cut_size: int) -> None:
    lights, _ = room_scene(3000, 10, 3)
    pts = diffuse_points(300, 9, occluder=True)
    tree = build_light_tree(*lights, seed=4)
    (pa, na), (pb, nb) = both(lambda: stochastic_cut(tree, pts, cut_size, clamp=1.0))
    assert np.array_equal(pa, pb) and np.array_equal(na, nb)
    a, b = both(lambda: stochastic_lightcut(tree, *lights, pts, np.random.default_rng(5),
                                            cut_size=cut_size))
    np.testing.assert_allclose(a.radiance, b.radiance, rtol=1e-12, atol=0.0)


def test_kernel_change_is_detected() -> None:
    """The comparison can fail: a kernel band of 0.5 instead of 0.25 changes the cuts."""
    from ercuts_core.integrators.ercuts import cut_rounds
    lights, pts = room_scene(2000, 200, 12)
    tree = build_light_tree(*lights, seed=1)
    with kernels.backend("numpy"):
        ref = lightcut(tree, *lights, pts, error_mode="total", max_cut_size=60)
    orig = cut_rounds.run_rounds

    def wrong(*args, **kw):
        return orig(*args, **dict(kw, band=0.5))
    lc_mod = sys.modules["ercuts_core.integrators.ercuts.lightcuts"]
    lc_mod.run_rounds = wrong
    try:
        with kernels.backend("numba"):
            bad = lightcut(tree, *lights, pts, error_mode="total", max_cut_size=60)
    finally:
        lc_mod.run_rounds = orig
    assert not np.array_equal(bad.radiance, ref.radiance)


def test_fallback_without_numba_warns_once_and_renders_the_same() -> None:
    """numba unimportable (a Blender without it): one RuntimeWarning naming why, then the numpy
    gather; its lightcut equals the compiled one of this process."""
    code = textwrap.dedent(f"""
        import sys, warnings
        sys.modules["numba"] = None          # import numba raises ImportError
        sys.path.insert(0, {ROOT!r})
        import numpy as np
        from ercuts_core import kernels
        from ercuts_core.integrators.ercuts.light_tree import build_light_tree
        from ercuts_core.integrators.ercuts.lightcuts import lightcut
        from tests.test_lightcuts import room_scene
        assert not kernels.NUMBA
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            lights, pts = room_scene(1500, 200, 21)
            tree = build_light_tree(*lights, seed=1)
            r = lightcut(tree, *lights, pts, error_mode="total")
            r = lightcut(tree, *lights, pts, error_mode="total")
        msgs = [str(w.message) for w in caught]
        print("WARN", len(msgs), msgs[0] if msgs else "")
        np.save(sys.argv[1], r.radiance)
    """)
    out = os.path.join(os.environ.get("TMPDIR", "/tmp"), f"ercuts_fallback_{os.getpid()}.npy")
    env = {k: v for k, v in os.environ.items() if k != kernels.ENV}
    proc = subprocess.run([sys.executable, "-c", code, out], capture_output=True, text=True,
                          timeout=300, cwd=ROOT, env=env)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "WARN 1 Ercuts: numba is not available (ModuleNotFoundError: import of numba" in proc.stdout
    lights, pts = room_scene(1500, 200, 21)
    tree = build_light_tree(*lights, seed=1)
    with kernels.backend("numba"):
        r = lightcut(tree, *lights, pts, error_mode="total")
    np.testing.assert_allclose(np.load(out), r.radiance, rtol=1e-12, atol=0.0)
    os.remove(out)


def test_brute_force_stops_after_one_block_when_cancelled() -> None:
    """Esc in the brute-force gather (issue 17): ``keep_going`` is polled after every block of
    ≤ 2^18 pairs, so a cancel waits for one block, not for the whole batch."""
    from ercuts_core.integrators.ercuts import lightcuts as lc
    lights, pts = room_scene(3000, 1000, 13)             # 3·10⁶ pairs: 12 blocks of 87 points
    blocks = -(-1000 // (lc._BRUTE_BLOCK // 3000))
    calls = []
    vis = pts.visible
    counted = lc.ShadingPoints(pts.p, pts.n, pts.wo, pts.f_bound, pts.eval_f,
                               lambda i, q, qn: calls.append(len(i)) or vis(i, q, qn))
    assert lc.brute_force(*lights, counted, keep_going=lambda: False) is None
    assert len(calls) == 1
    calls.clear()
    full = lc.brute_force(*lights, counted, keep_going=lambda: True)
    assert blocks > 1 and len(calls) == blocks
    np.testing.assert_array_equal(full, lc.brute_force(*lights, pts))


@pytest.mark.slow
def test_first_render_compiles_the_kernels_without_freezing(tmp_path) -> None:
    """With an empty numba cache (a machine's first render) the kernels compile in the
    background from the render's start (:mod:`~ercuts_core.integrators.ercuts.warm_up`): the
    render keeps reporting progress — no gap over 2 s, where compiling inside the gather took
    11–21 s — and says so while the gather waits for the compiler."""
    code = textwrap.dedent(f"""
        import json, sys, time
        sys.path.insert(0, {ROOT!r})
        from ercuts_core import RenderSettings, render
        from ercuts_core.scenes import closed_room
        stamps = []
        r = render(closed_room(16, 12), RenderSettings(rough_samples=2, chain_length=10, e1_samples=16,
                                                       direct_samples=2, stochastic_passes=1),
                   lambda f, m: stamps.append((time.perf_counter(), m)))
        gaps = [b[0] - a[0] for a, b in zip(stamps, stamps[1:])]
        print("RESULT", json.dumps(dict(gap=max(gaps), cancelled=r.cancelled,
                                        waited=any("compiling the kernels" in m for _, m in stamps))))
    """)
    env = {k: v for k, v in os.environ.items() if k != kernels.ENV}
    env["NUMBA_CACHE_DIR"] = str(tmp_path / "cold")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=600, cwd=ROOT, env=env)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    res = json.loads(proc.stdout.split("RESULT", 1)[1])
    assert not res["cancelled"] and res["waited"], res
    assert res["gap"] < 2.0, res
