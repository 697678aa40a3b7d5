"""ER chains: every mutation leaves the target distribution f invariant (chi² on binned marginals).

Chains started from seeds distributed ∝ f stay ∝ f at every step if the mutation satisfies
detailed balance (paper eq. 1). We draw seeds ∝ f by importance resampling a large pool of
path-traced seed paths, run each chain N steps with one mutation type, and compare the
final states' pixel-block and x2-position histograms with the expectation estimated from an
independent pool. Final states of different chains are (nearly) independent, so Pearson's
chi² applies. A chain with a deliberately wrong acceptance ratio must fail the same test.
"""
from __future__ import annotations

import numpy as np
import pytest
from scipy.special import gammaincc

from ercuts_core.integrators.ercuts.er_sampling import _VPLStore, chain_starts, run_chains
from ercuts_core.integrators.ercuts.initialization import seeds_from_path_tracer
from ercuts_core.integrators.ercuts.mutations import BIDIR, MUTATORS, MutationContext
from ercuts_core.integrators.ercuts.paths import PathBatch, contribution, is_target
from ercuts_core.scene import BuiltScene
from ercuts_core.scenes import cornell_box
from ercuts_core.validate import sanitize

W, H, DEPTH = 24, 18, 3


@pytest.fixture(scope="module")
def scene():
    return BuiltScene(sanitize(cornell_box(W, H, light="area")).desc)


def pool(scene, seed, passes):
    rng = np.random.default_rng(seed)
    parts, energies = [], []
    for _ in range(passes):
        p, e = seeds_from_path_tracer(scene, DEPTH, rng)
        parts.append(p)
        energies.append(e)
    return PathBatch.concat(parts), np.concatenate(energies)


def bins(paths: PathBatch) -> tuple[np.ndarray, np.ndarray]:
    """Pixel block (3×2 blocks) and x2 bin (height × left/right) of each path."""
    bx = np.clip((paths.raster[:, 0] / W * 3).astype(int), 0, 2)
    by = np.clip((paths.raster[:, 1] / H * 2).astype(int), 0, 1)
    x2 = paths.p[:, 2]
    hx = np.clip(((x2[:, 0] + 1) / 2 * 3).astype(int), 0, 2)
    hy = np.clip((x2[:, 1] / 2 * 3).astype(int), 0, 2)
    return by * 3 + bx, hy * 3 + hx


def chi2_pvalue(counts: np.ndarray, expected_p: np.ndarray) -> float:
    n = counts.sum()
    exp = expected_p * n
    keep = exp >= 5
    obs_rest, exp_rest = counts[~keep].sum(), exp[~keep].sum()
    o = np.append(counts[keep], obs_rest) if exp_rest >= 5 else counts[keep]
    e = np.append(exp[keep], exp_rest) if exp_rest >= 5 else exp[keep] * n / exp[keep].sum()
    stat = ((o - e) ** 2 / e).sum()
    dof = len(o) - 1
    return float(gammaincc(dof / 2, stat / 2))


def expected(paths, energy, which):
    b = bins(paths)[which]
    w = np.bincount(b, weights=energy, minlength=9)
    return w / w.sum()


@pytest.fixture(scope="module")
def pools(scene):
    seeds, e = pool(scene, 1, 120)
    ref, e_ref = pool(scene, 2, 120)
    return seeds, e, ref, e_ref


def resample(seeds, e, n, rng):
    idx = rng.choice(len(e), size=n, p=e / e.sum())
    return seeds.take(idx)


def run(scene, start, enabled, n_steps, rng):
    ctx = MutationContext(scene, DEPTH + 1)
    res = run_chains(ctx, start, np.ones(len(start), np.int64), n_steps, enabled, rng)
    return res


def final_states(scene, start, mutator, n_steps, rng, break_ratio=1.0):
    """Run chains of one mutation type and return the final paths."""
    ctx = MutationContext(scene, DEPTH + 1)
    x = start.copy()
    f = contribution(scene, x)
    y_x = f @ np.array([0.2126, 0.7152, 0.0722])
    for _ in range(n_steps):
        prop = MUTATORS[mutator](ctx, x, rng)
        fy = contribution(scene, prop.paths) @ np.array([0.2126, 0.7152, 0.0722])
        ok = prop.valid & is_target(scene, prop.paths)
        a = np.where(ok, np.minimum(1, fy * prop.ratio * break_ratio / np.maximum(y_x, 1e-300)), 0)
        assert np.isfinite(a).all()
        acc = rng.random(len(x)) < a
        x.put(np.flatnonzero(acc), prop.paths.take(np.flatnonzero(acc)))
        y_x[acc] = fy[acc]
    return x


SIG = 1 - (1 - 0.01) ** (1 / 8)     # Šidák over the 8 chi² tests of this module


@pytest.mark.slow
@pytest.mark.parametrize("mutator,which", [(0, 0), (1, 0), (BIDIR, 1), (BIDIR, 0)])
def test_mutation_preserves_target_distribution(scene, pools, mutator, which):
    seeds, e, ref, e_ref = pools
    rng = np.random.default_rng(10 + mutator)
    start = resample(seeds, e, 3000, rng)
    end = final_states(scene, start, mutator, 12, rng)
    counts = np.bincount(bins(end)[which], minlength=9)
    p = chi2_pvalue(counts, expected(ref, e_ref, which))
    assert p > SIG, (counts, expected(ref, e_ref, which) * counts.sum(), p)


@pytest.mark.slow
def test_a_wrong_acceptance_ratio_is_detected(scene, pools):
    """The same test rejects the bidirectional mutation with its ratio inflated ×3 for long paths."""
    seeds, e, ref, e_ref = pools
    rng = np.random.default_rng(99)
    start = resample(seeds, e, 3000, rng)
    ctx = MutationContext(scene, DEPTH + 1)
    x = start.copy()
    lum = np.array([0.2126, 0.7152, 0.0722])
    y_x = contribution(scene, x) @ lum
    for _ in range(12):
        prop = MUTATORS[BIDIR](ctx, x, rng)
        fy = contribution(scene, prop.paths) @ lum
        bias = np.where(prop.paths.k > x.k, 3.0, 1.0)        # favour longer paths: wrong
        a = np.where(prop.valid, np.minimum(1, fy * prop.ratio * bias / np.maximum(y_x, 1e-300)), 0)
        acc = rng.random(len(x)) < a
        x.put(np.flatnonzero(acc), prop.paths.take(np.flatnonzero(acc)))
        y_x[acc] = fy[acc]
    # Path length histogram against the expected one.
    k_counts = np.bincount(x.k, minlength=DEPTH + 2)[2:]
    k_exp = np.bincount(ref.k, weights=e_ref, minlength=DEPTH + 2)[2:]
    assert chi2_pvalue(k_counts, k_exp / k_exp.sum()) < 1e-6


@pytest.mark.slow
def test_bidirectional_mutation_preserves_path_length_distribution(scene, pools):
    seeds, e, ref, e_ref = pools
    rng = np.random.default_rng(5)
    end = final_states(scene, resample(seeds, e, 3000, rng), BIDIR, 12, rng)
    k_counts = np.bincount(end.k, minlength=DEPTH + 2)[2:]
    k_exp = np.bincount(ref.k, weights=e_ref, minlength=DEPTH + 2)[2:]
    assert chi2_pvalue(k_counts, k_exp / k_exp.sum()) > SIG


def test_chain_run_statistics_and_vpl_bookkeeping(scene, pools):
    seeds, e, _, _ = pools
    rng = np.random.default_rng(3)
    start = resample(seeds, e, 200, rng)
    res = run(scene, start, (True, True, True, True), 10, rng)
    assert res.nan_acceptances == 0
    assert res.proposed[2] == 0                          # no specular chains: multichain never applies
    assert res.proposed.sum() == 200 * 10
    assert res.count.sum() == 200 * 10                   # one deposit per state
    assert res.deposits_per_pixel.sum() == 200 * 10
    # Lens/caustic moves keep x2: VPLs are created only by seeds and accepted bidirectional moves.
    assert res.n_vpls == 200 + res.accepted[BIDIR]
    assert np.all(res.count >= 0) and np.allclose(np.linalg.norm(res.normal, axis=1), 1)


def test_vpls_stand_on_the_geometric_normal():
    """A VPL stands for a small diffuse patch at x2 (Keller 1997): its light leaves as the
    patch's projected area, cosθ about the *geometric* normal, facing x1. A normal map's
    shading normal only changes how the patch reflects (already in the VPL's colour): as the
    emission axis it tilted every VPL on a normal-mapped floor (tests/blender/
    test_gltf_cycles.py: the floor's VPL light 8–30 % off in the blocks it shines on)."""
    paths = PathBatch.empty(2, 4)
    tilt = np.array([np.sin(0.44), 0.0, np.cos(0.44)])          # a 25° normal-map tilt
    paths.p[:, 1] = [[0.3, 0.0, 1.0], [0.3, 0.0, 1.0]]          # x1 above x2 in both
    paths.ng[:, 2] = [[0.0, 0.0, 1.0], [0.0, 0.0, -1.0]]        # either winding
    paths.ns[:, 2] = [tilt, -tilt]
    paths.k[:] = 3
    store = _VPLStore(4)
    ids = store.add(paths)
    assert np.allclose(store.normal[ids], [[0.0, 0.0, 1.0], [0.0, 0.0, 1.0]])


def test_chain_starts_is_unbiased():
    rng = np.random.default_rng(0)
    energy = rng.exponential(size=2000)
    starts = np.mean([chain_starts(energy, 10, 0.05, rng) for _ in range(200)], axis=0)
    np.testing.assert_allclose(starts, energy / (10 * 0.05), atol=0.25)


def test_interrupt_abandons_the_step_without_its_deposits(scene, pools):
    """interrupt(fraction) is polled between a step's mutation groups; False stops at once,
    leaving only the complete steps' deposits (keep_going stops between steps)."""
    seeds, e, _, _ = pools
    start = resample(seeds, e, 200, np.random.default_rng(3))
    ctx = MutationContext(scene, DEPTH + 1)
    polls = []

    def interrupt(fraction):
        polls.append(fraction)
        return len(polls) <= 5

    res = run_chains(ctx, start, np.ones(len(start), np.int64), 10, (True, True, True, True),
                     np.random.default_rng(3), interrupt=interrupt)
    assert len(polls) == 6 and polls == sorted(polls) and polls[-1] < 0.3
    assert 0 < res.steps_done < 3 and res.count.sum() == 200 * res.steps_done


def test_thinned_vpls_keep_the_energy_in_expectation():
    """A paced iteration that cannot give every VPL ``vpl.PACED_E1_FLOOR`` Ê1 samples keeps a
    random share of them (``vpl.thin_vpls``): each record survives with probability q and
    then carries 1/q of its deposits and colour, so Σ count (the image energy in units of
    e_d) and Σ colour are kept in expectation — within 4 standard errors over 200 draws —
    and about q·V records remain; q ≥ 1 keeps the records as they are."""
    from ercuts_core.integrators.ercuts.er_sampling import ChainResult
    from ercuts_core.integrators.ercuts.vpl import thin_vpls

    rng = np.random.default_rng(3)
    V = 2000
    count = rng.integers(1, 20, V).astype(np.float64)
    color = rng.random((V, 3)) * count[:, None]
    chains = ChainResult(rng.random((V, 3)), np.tile([0.0, 1.0, 0.0], (V, 1)), count, color,
                         rng.random((V, 2)), np.zeros(4), np.zeros(4), np.zeros(4), V, 10)
    assert thin_vpls(chains, 1.0, rng) is chains
    q = 0.3
    draws = [thin_vpls(chains, q, rng) for _ in range(200)]
    sums = np.array([d.count.sum() for d in draws])
    colors = np.array([d.color_sum.sum(axis=0) for d in draws])
    kept = np.array([(d.count > 0).sum() for d in draws])
    assert abs(sums.mean() - count.sum()) < 4 * sums.std(ddof=1) / np.sqrt(len(sums))
    se = colors.std(axis=0, ddof=1) / np.sqrt(len(colors))
    assert (np.abs(colors.mean(axis=0) - color.sum(axis=0)) < 4 * se).all()
    assert abs(kept.mean() - q * V) < 4 * np.sqrt(q * (1 - q) * V / len(kept))
    d = draws[0]
    on = d.count > 0
    assert np.allclose(d.count[on], count[on] / q) and np.allclose(d.color_sum[on], color[on] / q)


def test_a_paced_iteration_thins_the_vpls_before_it_cuts_their_e1_samples():
    """``vpl.paced_vpl_share``: with time for half of ``e1_samples`` (256) per VPL a paced
    iteration keeps half of the VPLs, each normalised with all 256 samples; with time for
    more it keeps them all; with very little, at least ``MIN_VPL_SHARE`` of them. With the
    floor of 128 samples used until stop 50 the first case kept every VPL at 128 samples
    each, which made the door's VPL image at 640×480 4–8 % too bright (1/Ê1's tail)."""
    from ercuts_core.integrators.ercuts.vpl import MIN_VPL_SHARE, paced_vpl_share

    assert paced_vpl_share(128 * 100_000, 100_000, 256) == pytest.approx(0.5)
    assert paced_vpl_share(300 * 100_000, 100_000, 256) > 1.0
    assert paced_vpl_share(1_000, 100_000, 256) == MIN_VPL_SHARE
    # a render asking for fewer samples than the floor keeps its own count
    assert paced_vpl_share(64 * 1_000, 1_000, 64) == pytest.approx(1.0)
