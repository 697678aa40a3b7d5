"""The whole Ercuts algorithm: energy, agreement with a converged path-traced image, ablations,
statistics, time limit and cancellation."""
from __future__ import annotations

import os
import time

import numpy as np
import pytest

from benchmarks.metrics import relmse
from ercuts_core import RenderSettings, render
from ercuts_core.integrators.ercuts.balance import passes_at_equal_cost
from ercuts_core.sampling import luminance
from ercuts_core.scenes import closed_room, s_corridor

HERE = os.path.dirname(os.path.abspath(__file__))
REF = os.path.join(HERE, "data", "closed_room_48x36_path_2048spp.npz")
FAST = dict(integrator="ERCUTS", rough_samples=8, chain_length=40, chains_per_pixel=0.5)


@pytest.fixture(scope="module")
def reference():
    """Converged path-traced reference (mean and per-pixel variance of the mean), made by
    ``python tests/make_references.py`` and stored with the tests."""
    z = np.load(REF)
    return z["mean"], z["var"]


@pytest.fixture(scope="module", params=["NEE", "VPL"])
def ercuts_room(request):
    """The closed room with direct light by next-event estimation (default) and by VPLs."""
    return render(closed_room(48, 36), RenderSettings(**FAST, seed=1, direct_light=request.param))


def test_energy_agrees_with_bdpt(ercuts_room):
    """ERCUTS's image energy is within 3 % of BDPT's (paper: each path carries P/n). No
    rescale to P hides the VPL normalisation any more (``normalize_to_p`` is off), so this
    fails when it is wrong (test_injected_normalisation_error_shows_in_the_image)."""
    bdpt = [render(closed_room(48, 36), RenderSettings(integrator="BDPT", samples=16, seed=s)).image
            for s in range(3)]
    e_b = np.mean([luminance(b[..., :3]).mean() for b in bdpt])
    e_e = luminance(ercuts_room.image[..., :3]).mean()
    assert abs(e_e / e_b - 1) < 0.03, (e_e, e_b)


def test_image_agrees_with_converged_path_tracing(ercuts_room, reference):
    """relMSE against the converged reference ≤ 0.03 (measured 0.006 with direct light by
    next-event estimation, 0.010 with direct light by VPLs; the residual is the VPL
    approximation — clamped and blurred near creases — plus chain noise). The same
    budget of plain BDPT (16 spp, 3× the time) lands near 0.003 in this easy, directly lit room;
    the corridor benchmark is where ERCUTS wins."""
    mean, var = reference
    assert np.sqrt(var).mean() / mean.mean() < 0.02          # the reference is converged
    assert relmse(ercuts_room.image[..., :3], mean[..., :3]) < 0.03


def test_statistics_and_diagnostic_images(ercuts_room):
    st = ercuts_room.stats
    for key in ("P", "chains", "chain_states", "vpls_before_merge", "vpls_after_merge", "vpls",
                "acceptance_lens", "acceptance_caustic", "acceptance_bidirectional", "cut_size_mean",
                "cut_size_max", "clamped_energy", "vpl_energy_ratio"):
        assert key in st, key
    assert st["nan_acceptances"] == 0 and st["nonfinite_samples"] == 0
    assert st["vpls_after_merge"] < st["vpls_before_merge"]
    if "direct_samples" in st:      # NEE: direct light in its own passes, VPLs indirect only
        # the passes that cost what direct_samples passes with one light sample would
        k = st["direct_light_samples"]
        assert st["direct_samples"] == 2 + passes_at_equal_cost(RenderSettings().direct_samples, 2, 2, k)
        assert st["vpls_emitter"] == 0
        assert 0 < st["P"] < st["P_all"]
    else:                           # VPL: the area light's VPLs carry the direct light
        assert st["vpls_emitter"] > 0 and "direct" not in ercuts_room.timings
    # the multi-chain perturbation cannot apply without specular lobes: not reported (issue 12)
    assert 0 < st["acceptance_bidirectional"] < 1 and "proposed_multichain" not in st
    assert 1 <= st["cut_size_mean"] <= st["cut_size_max"] <= 1000
    for phase in ("bdpt", "chains", "vpls", "tree", "cuts"):
        assert ercuts_room.timings[phase] >= 0
    aov = ercuts_room.aovs
    assert aov["cut_size"].shape == (36, 48, 1) and aov["cut_size"].max() >= 1
    assert aov["chain_deposits"].shape == (36, 48, 1)
    assert aov["chain_deposits"].sum() == st["chain_states"]
    assert np.isfinite(ercuts_room.image).all()


def test_brute_force_gather_matches_lightcuts():
    """The ablation (every VPL at every point) and the bounded tree gather agree to within the
    2 % rule."""
    s = RenderSettings(**FAST, seed=2, gather="LIGHTCUTS")
    a = render(closed_room(32, 24), s).image[..., :3]
    b = render(closed_room(32, 24), s.replace(gather="BRUTE_FORCE")).image[..., :3]
    assert relmse(a, b) < 1e-3
    assert abs(a.mean() / b.mean() - 1) < 0.02


def test_same_seed_same_image():
    s = RenderSettings(**FAST, seed=4)
    a = render(closed_room(24, 18), s).image
    b = render(closed_room(24, 18), s).image
    np.testing.assert_array_equal(a, b)


def test_time_limit_covers_all_phases():
    t0 = time.perf_counter()
    r = render(s_corridor(160, 120), RenderSettings(integrator="ERCUTS", rough_samples=64, chain_length=200,
                                                    chains_per_pixel=1.0, time_limit=6.0))
    elapsed = time.perf_counter() - t0
    assert elapsed < 6.0 + 2.0, elapsed
    assert r.image[..., :3].mean() > 0


@pytest.mark.parametrize("phase", ["BDPT", "chains", "Lightcuts"])
def test_cancel_in_each_phase_returns_an_image(phase):
    def progress(fraction, message):
        return phase not in message

    r = render(closed_room(24, 18), RenderSettings(**FAST, seed=5), progress)
    assert r.cancelled
    assert r.image.shape == (18, 24, 4) and np.isfinite(r.image).all()


def test_gather_order_is_a_permutation_of_coherent_runs():
    from ercuts_core.integrators.ercuts.gather import GATHER_RUN, spread_order as _spread_order

    pts = np.flatnonzero(np.random.default_rng(0).random(5000) < 0.7)
    order = _spread_order(pts, seed=3)
    np.testing.assert_array_equal(np.sort(order), pts)                  # every point once
    np.testing.assert_array_equal(order, _spread_order(pts, seed=3))     # deterministic
    # a run is GATHER_RUN consecutive entries of pts (neighbouring pixels), except the short last run
    pos = np.searchsorted(pts, order)
    steps = np.diff(pos)
    assert np.mean(steps == 1) > 1 - 1.5 / GATHER_RUN
    # the first batch (256 points) samples the whole image, not its first rows
    assert pos[:256].max() - pos[:256].min() > 0.8 * len(pts)


def test_gather_pace_raises_the_error_then_caps_and_recovers():
    from ercuts_core.integrators.ercuts.pacing import MAX_PACED_ERROR, GatherPace

    pace = GatherPace(0.02, 1000)
    pace.update(256, 1.0, 500.0, 10_000, float("inf"))                   # no time limit
    assert (pace.error, pace.cap) == (0.02, 1000)
    pace.update(256, 0.256, 500.0, 10_000, 20.0)                        # 1 ms/pt, 10 s of 18: on time
    assert (pace.error, pace.cap) == (0.02, 1000)
    pace.update(256, 0.256, 500.0, 10_000, 2.0)                         # 5.6× behind schedule
    assert pace.error == pytest.approx(0.02 * 10 / 1.8) and pace.cap == 1000
    pace.update(256, 0.256, 100.0, 10_000, 0.18)                        # still behind at the largest ε
    assert pace.error == MAX_PACED_ERROR
    pace.update(256, 0.256, 100.0, 10_000, 1.0)                         # only now the cap
    assert pace.error == MAX_PACED_ERROR and pace.cap == int(100 / (10 / 0.9))
    cap = pace.cap
    pace.update(256, 0.0256, float(cap), 10_000, 10.0)                  # far ahead: lift the cap first
    assert pace.error == MAX_PACED_ERROR and pace.cap > cap
    for _ in range(5):
        pace.update(256, 0.0256, float(pace.cap), 10_000, 10.0)
    assert pace.cap == 1000 and pace.error < MAX_PACED_ERROR              # then lower ε again
    for _ in range(10):
        pace.update(256, 0.001, 10.0, 10_000, 10.0)
    assert pace.error == 0.02                                            # never below max_error
    stats = {}
    pace.record(stats, 256 * 16)
    assert stats["max_error_for_time_limit"] == MAX_PACED_ERROR and stats["cut_cap_for_time_limit"] == cap
    assert 0 < stats["paced_points_for_time_limit"] < 1


def test_phase_deadlines_follow_the_shares():
    """Each phase's deadline is its share of the time left over the shares still to come
    (the gather's included); the direct-light share exists only with direct_light='NEE' and
    grows with the rough image's direct fraction, shrinking the others."""
    from types import SimpleNamespace

    from ercuts_core.integrators.ercuts.pacing import Schedule

    now = time.perf_counter()
    clock = SimpleNamespace(deadline=now + 100.0)
    nee = Schedule(clock, direct_vpls=False)
    vpl = Schedule(clock, direct_vpls=True)
    assert vpl.deadline("bdpt") - now == pytest.approx(15.0, abs=0.05)     # 0.15 / 1
    assert vpl.deadline("chains") - now == pytest.approx(100 * 0.30 / 0.85, abs=0.05)
    assert nee.deadline("bdpt") - now == pytest.approx(15.0, abs=0.05)
    assert nee.deadline("direct") - now == pytest.approx(100 * 0.05 / 0.85, abs=0.05)
    nee.share["direct"] = 0.5                        # a directly lit scene; the gather keeps 0.35
    assert nee.deadline("direct") - now == pytest.approx(100 * 0.5 / 1.30, abs=0.05)
    assert nee.deadline("chains") - now == pytest.approx(100 * 0.30 / 0.80, abs=0.05)
    nee.grow_direct(1.0)                             # all direct: 0.05 + 0.45
    assert nee.share["direct"] == pytest.approx(0.5)
    assert Schedule(SimpleNamespace(deadline=None), direct_vpls=False).deadline("bdpt") is None


def test_vpl_image_energy_matches_p(ercuts_room):
    """The VPL image's own energy (``vpl_energy_ratio``) is P within 5 % (measured 1.01 in
    this room with either direct-light mode; benchmarks/results/e1_bias.md)."""
    assert abs(ercuts_room.stats["vpl_energy_ratio"] - 1) < 0.05


def test_vpl_energy_check_detects_a_wrong_normalisation(monkeypatch):
    """An injected error — every Ê1 15 % low, so every VPL 18 % too bright — fails the
    check above, and it shows in the image: the indirect light is 18 % brighter, and the
    ``normalize_to_p`` ablation would have hidden it."""
    from ercuts_core.integrators.ercuts import vpl

    settings = RenderSettings(**FAST, seed=1)
    good = render(closed_room(48, 36), settings)
    real = vpl.estimate_e1_allocated
    monkeypatch.setattr(vpl, "estimate_e1_allocated", lambda *a, **kw: 0.85 * real(*a, **kw))
    res = render(closed_room(48, 36), settings)
    assert res.stats["vpl_energy_ratio"] > 1.1
    assert luminance(res.image[..., :3]).mean() > 1.03 * luminance(good.image[..., :3]).mean()
    hidden = render(closed_room(48, 36), settings.replace(normalize_to_p=True))
    assert luminance(hidden.image[..., :3]).mean() < 1.03 * luminance(good.image[..., :3]).mean()


def test_max_chains_caps_the_chains_and_keeps_the_energy():
    """With ``max_chains`` below chains_per_pixel · pixels, seeds come from a quarter of the
    pixel samples (``seed_samples`` per pixel uncapped: a quarter of those, energies ÷ q) and
    about max_chains chains run (Σ⌊U + e/(N·e_d)⌋ has
    expectation max_chains · seed energy / P, measured within 15 % of it here); the image
    energy stays that of the uncapped render within the 3 % of the energy test above."""
    room = closed_room(48, 36)
    full = render(room, RenderSettings(**FAST, seed=2))
    cap = int(FAST["chains_per_pixel"] * 48 * 36 / 4)
    capped = render(room, RenderSettings(**FAST, seed=2, max_chains=cap, min_chain_length=FAST["chain_length"]))
    m = RenderSettings().seed_samples
    assert capped.stats["seed_pixels"] == m * 48 * 36 // 4
    assert full.stats["seed_pixels"] == m * 48 * 36
    assert abs(capped.stats["chains"] / cap - 1) < 0.15, capped.stats["chains"]
    e_full, e_cap = (luminance(r.image[..., :3]).mean() for r in (full, capped))
    assert abs(e_cap / e_full - 1) < 0.03, (e_cap, e_full)


def test_beyond_max_chains_the_steps_spread_over_shorter_chains():
    """Beyond ``max_chains`` the chains keep the mutation steps max_chains · chain_length and
    spread them over more, shorter chains, down to ``min_chain_length`` (``chain_plan``):
    here half the pixel samples seed twice the capped count of chains of half the length, about
    that many chains run (within 15 %, as above) and the energy stays the uncapped render's
    within 3 %."""
    room = closed_room(48, 36)
    n = 48 * 36
    cap = int(FAST["chains_per_pixel"] * n / 4)
    settings = RenderSettings(**FAST, seed=2, max_chains=cap, min_chain_length=FAST["chain_length"] // 2)
    assert settings.chain_plan(n) == (2 * cap, FAST["chain_length"] // 2)
    spread = render(room, settings)
    assert spread.stats["chain_length"] == FAST["chain_length"] // 2
    assert spread.stats["seed_pixels"] == RenderSettings().seed_samples * n // 2
    assert abs(spread.stats["chains"] / (2 * cap) - 1) < 0.15, spread.stats["chains"]
    full = render(room, RenderSettings(**FAST, seed=2))
    e_full, e_spread = (luminance(r.image[..., :3]).mean() for r in (full, spread))
    assert abs(e_spread / e_full - 1) < 0.03, (e_spread, e_full)


def test_a_paced_iteration_stops_seeding_at_its_deadline(monkeypatch):
    """Under a time limit the seed paths stop at their deadline (here at once: SEED_SHARE =
    0, so after the first of three 1024-pixel batches of the seed samples in a random order);
    the chains from that random third of the pixels still carry the image's energy (within
    3 % of the render that seeds every pixel, as in the tests above)."""
    from ercuts_core.integrators.ercuts import integrator as ercuts_integrator

    room = closed_room(64, 48)
    fast = dict(FAST, seed=4, batch_rays=1 << 15, time_limit=12.0, iterations=1, seed_samples=1)
    full = render(room, RenderSettings(**fast))
    assert full.stats["seed_pixels"] == 64 * 48 and "seed_pixels_planned" not in full.stats
    monkeypatch.setattr(ercuts_integrator, "SEED_SHARE", 0.0)
    cut = render(room, RenderSettings(**fast))
    assert cut.stats["seed_pixels"] == 1024 and cut.stats["seed_pixels_planned"] == 64 * 48
    e_full, e_cut = (luminance(r.image[..., :3]).mean() for r in (full, cut))
    assert abs(e_cut / e_full - 1) < 0.03, (e_cut, e_full)


def test_a_paced_iterations_seed_samples_come_in_a_uniformly_random_order():
    """The seed samples a paced iteration traces before its deadline are a uniform random
    subset of the image (:func:`~ercuts_core.integrators.ercuts.seeding.seed_order`): the
    first 1 024 of 160×120's 76 800 (four per pixel) fall into ten bands of 12 rows as a
    multinomial(1024, 1/10) does, each count within 5 standard deviations (9.6) of 102.4 in
    all of eight orders. Shuffling the 4 096-sample batches instead (until stop 49) put the
    whole prefix into 1.6 rows."""
    from ercuts_core.integrators.ercuts.seeding import seed_order, seed_pixels

    pix, _ = seed_pixels(160 * 120, 4.0, np.random.default_rng(0))
    sd = np.sqrt(1024 * 0.1 * 0.9)
    for seed in range(8):
        order = seed_order(pix, seed)
        np.testing.assert_array_equal(np.sort(order), pix)
        bands = np.bincount(order[:1024] // 160 // 12, minlength=10)
        assert np.all(np.abs(bands - 102.4) < 5 * sd), bands
    batches = np.random.default_rng([0, 0x5EED]).permutation(np.arange(0, len(pix), 4096))
    old = np.bincount(pix[batches[0]:batches[0] + 1024] // 160 // 12, minlength=10)
    assert not np.all(np.abs(old - 102.4) < 5 * sd)     # the test tells the two apart


def test_the_default_chain_plan_by_resolution():
    """Defaults: up to 256×256 every pixel's c = 0.25 chains of 100 steps (160×120 unchanged);
    at 640×480 (76 800 chains of 21 steps) and beyond 1.64 M steps in chains of 20 (81 920
    chains) at any resolution."""
    s = RenderSettings()
    assert s.chain_plan(160 * 120) == (0.25 * 160 * 120, 100)
    assert s.chain_plan(256 * 256) == (16384, 100)
    assert s.chain_plan(320 * 240) == (0.25 * 320 * 240, 85)
    assert s.chain_plan(640 * 480) == (0.25 * 640 * 480, 21)
    for n in (1280 * 720, 1920 * 1080):
        assert s.chain_plan(n) == (81920, 20)


def test_seed_pixels_sample_every_pixel_rate_times_on_average():
    """Every pixel ⌊rate⌋ times, a random subset once more; the realised rate is returned
    (rate 1: each pixel once, as in the paper; below 1: a random subset, at least one)."""
    from ercuts_core.integrators.ercuts.seeding import seed_pixels

    rng = np.random.default_rng(3)
    pix, q = seed_pixels(100, 2.3, rng)
    counts = np.bincount(pix, minlength=100)
    assert set(counts) == {2, 3} and counts.sum() == 230 and q == pytest.approx(2.3)
    assert (np.diff(pix) >= 0).all()
    pix, q = seed_pixels(100, 1.0, rng)
    np.testing.assert_array_equal(pix, np.arange(100))
    assert q == 1.0
    pix, q = seed_pixels(100, 0.3, rng)
    assert len(np.unique(pix)) == len(pix) == 30 and q == pytest.approx(0.3)
    assert len(seed_pixels(100, 1e-6, rng)[0]) == 1


def test_the_seed_rate_by_resolution():
    """``seed_samples`` (4) seeds per pixel while they fit in the seed budget (160×120),
    fewer at 320×240, and from 640×480 up what one seed sample gives (every pixel, or the
    chains' share of them when the chain cap binds)."""
    from ercuts_core.settings import SEED_SAMPLE_BUDGET

    s, one = RenderSettings(), RenderSettings(seed_samples=1)
    assert s.seed_rate(160 * 120) == 4.0 and one.seed_rate(160 * 120) == 1.0
    assert s.seed_rate(320 * 240) == pytest.approx(SEED_SAMPLE_BUDGET / (320 * 240))
    for n in (640 * 480, 1280 * 720, 1920 * 1080):
        assert s.seed_rate(n) == one.seed_rate(n) <= 1.0
    assert one.seed_rate(1920 * 1080) == pytest.approx(81920 / (0.25 * 1920 * 1080))


def test_several_seeds_per_pixel_are_independent_samples():
    """Σe/q of the seeds estimates the image's indirect energy at any seed rate, and with 4
    seeds per pixel its variance is a quarter of one seed's: the repeated pixels take
    independent BDPT samples. 60 draws each: the variance ratio 4·F(59, 59) exceeds 4 × its
    0.1 % quantile with probability 0.999 (identical repeats would give 1·F); means within
    4 standard errors."""
    from scipy.stats import f as f_dist

    from ercuts_core.integrators.ercuts.seeding import seed_paths, seed_pixels
    from ercuts_core.scene import BuiltScene
    from ercuts_core.scenes import cornell_box
    from ercuts_core.validate import sanitize

    scene = BuiltScene(sanitize(cornell_box(16, 12, "mesh")).desc)
    settings = RenderSettings(max_depth=5)
    n, K = scene.camera.window.n_pixels, 60

    def energy(rate, seed):
        rng = np.random.default_rng(seed)
        pix, q = seed_pixels(n, rate, rng)
        return seed_paths(scene, settings, rng, pix)[1].sum() / q

    e1 = np.array([energy(1.0, s) for s in range(K)])
    e4 = np.array([energy(4.0, 1000 + s) for s in range(K)])
    scene.close()
    se = np.sqrt(e1.var(ddof=1) / K + e4.var(ddof=1) / K)
    assert abs(e1.mean() - e4.mean()) < 4 * se, (e1.mean(), e4.mean(), se)
    ratio = e1.var(ddof=1) / e4.var(ddof=1)
    assert ratio > 4 * f_dist.ppf(1e-3, K - 1, K - 1), ratio


def test_rough_image_follows_a_budget_not_the_pixels():
    """Step 1 only measures P (and previews): 16 spp at full resolution up to 2^19 camera
    samples (160×120), beyond it a lower resolution — 1/4 at 640×480, 1/8 at 1920×1080."""
    from ercuts_core.integrators.ercuts.initialization import rough_factor

    assert rough_factor(160 * 120, 16) == 1
    assert rough_factor(640 * 480, 16) == 4
    assert rough_factor(1920 * 1080, 16) == 8
    assert rough_factor(10, 4) == 1


def test_rough_camera_sees_the_same_view():
    """The low-resolution rough camera's rays through a point of the frame are the full
    camera's rays through the same point of the frame (non-square pixels, border, shift)."""
    import dataclasses

    from ercuts_core.camera import Camera
    from ercuts_core.integrators.ercuts.initialization import rough_camera

    desc = dataclasses.replace(closed_room(101, 67).camera, pixel_aspect_x=1.3, shift_x=0.1,
                               use_border=True, border=(0.1, 0.2, 0.7, 0.9))
    full, low = Camera(desc), Camera(rough_camera(desc, 4))
    assert (low.width, low.height) == (25, 17)
    u = np.random.default_rng(0).random((50, 2))             # positions as fractions of the frame
    for a, b in zip(full.generate_rays(u * [101, 67]), low.generate_rays(u * [25, 17])):
        np.testing.assert_allclose(a, b, atol=1e-12)


def test_low_resolution_rough_image_measures_the_same_energy(monkeypatch):
    """P from a rough image at 1/2 of the resolution (the budget forced down) agrees with P
    at full resolution within 4 standard errors of the difference (spread over 4 seeds each)."""
    from ercuts_core.integrators.ercuts import initialization

    def P(budget, seed):
        monkeypatch.setattr(initialization, "ROUGH_SAMPLE_BUDGET", budget)
        cheap = dict(chain_length=1, chains_per_pixel=0.05, direct_samples=1, e1_samples=4,
                     gather="STOCHASTIC", stochastic_cut_size=4, stochastic_passes=1)   # only P matters
        r = render(closed_room(48, 36), RenderSettings(rough_samples=8, seed=seed, iterations=1, **cheap))
        return r.stats["P"], r.stats["rough_resolution"]

    full = [P(1 << 19, s) for s in range(4)]
    low = [P(48 * 36 * 8 // 4, s) for s in range(4)]          # 2 spp·(24×18) … k = 2
    assert {w for _, w in full} == {48} and {w for _, w in low} == {24}
    a, b = np.array([p for p, _ in full]), np.array([p for p, _ in low])
    se = np.sqrt(a.var(ddof=1) / len(a) + b.var(ddof=1) / len(b))
    assert abs(a.mean() - b.mean()) < 4 * se + 1e-12, (a, b)


def test_p_relative_error_is_the_standard_error_of_the_mean():
    """s/(√n·mean) over the passes' energies; undefined (inf) from one pass or at P = 0."""
    from ercuts_core.integrators.ercuts.initialization import p_relative_error

    assert p_relative_error([1.0, 2.0, 3.0]) == pytest.approx(1.0 / np.sqrt(3) / 2.0)
    assert p_relative_error([5.0, 5.0, 5.0, 5.0]) == 0.0
    assert p_relative_error([5.0]) == np.inf and p_relative_error([0.0, 0.0]) == np.inf


@pytest.mark.parametrize("target, passes", [(1.0, 4), (0.0, 12)])
def test_rough_bdpt_stops_once_p_is_known(monkeypatch, target, passes):
    """The rough BDPT stops after ROUGH_MIN_PASSES passes once P's relative standard error
    is within ROUGH_P_ERROR (a target of 100 %: at once), and runs all ``rough_samples``
    while it is not (a target of 0); the error is reported."""
    from ercuts_core.integrators.ercuts import integrator as ercuts_integrator

    monkeypatch.setattr(ercuts_integrator, "ROUGH_P_ERROR", target)
    cheap = dict(chain_length=1, chains_per_pixel=0.05, direct_samples=1, e1_samples=4,
                 gather="STOCHASTIC", stochastic_cut_size=4, stochastic_passes=1)
    r = render(closed_room(32, 24), RenderSettings(rough_samples=12, seed=1, iterations=1, **cheap))
    assert r.stats["bdpt_samples"] == passes
    assert 0.0 < r.stats["P_relative_error"] < 0.2


def test_stochastic_gather_agrees_with_brute_force():
    """The stochastic gather is unbiased for the VPLs: on the same VPLs (same seed) its
    image energy is the brute-force gather's within 1 % (measured 0.2 %: 768 pixels of
    about 10 % noise each) and its relMSE is noise of the expected size (measured 0.004)."""
    s = RenderSettings(**FAST, seed=2)
    a = render(closed_room(32, 24), s.replace(gather="STOCHASTIC")).image[..., :3]
    b = render(closed_room(32, 24), s.replace(gather="BRUTE_FORCE")).image[..., :3]
    assert abs(luminance(a).mean() / luminance(b).mean() - 1) < 0.01
    assert relmse(a, b) < 0.02


def test_stochastic_gather_uses_the_time_left_for_more_passes():
    """Without a time limit the stochastic gather makes ``stochastic_passes`` passes; under one,
    the last iteration repeats passes while another fits and averages them."""
    s = RenderSettings(**FAST, seed=3, gather="STOCHASTIC", stochastic_passes=1)
    one = render(closed_room(32, 24), s)
    assert one.stats["gather_passes"] == 1
    assert render(closed_room(32, 24), s.replace(stochastic_passes=3)).stats["gather_passes"] == 3
    paced = render(closed_room(32, 24), s.replace(time_limit=6.0, iterations=1))
    assert paced.stats["gather_passes"] >= 2
    assert np.isfinite(paced.image).all()


def test_direct_passes_take_more_light_samples_only_under_soft_shadows():
    """After two pilot passes with two light samples the direct passes take as many as the
    light's share of their variance asks for (``balance.light_samples_for``), in as many
    passes as cost what ``direct_samples`` passes with one would: under the directly lit
    scene's 2 m panel (soft shadows) more than one (four at 160×120; two at this 48×36,
    whose larger pixels make the jitter's part larger), and under one point light — whose
    light sample has no variance at all — one."""
    import dataclasses
    from ercuts_core.scenes import directly_lit, point_lit_box
    fast = dict(FAST, direct_samples=6, shading_samples=1)
    soft = render(directly_lit(48, 36), RenderSettings(seed=1, **fast))
    box = point_lit_box()                   # its point light alone (with the spot: two lights)
    pl = box.point_lights
    one = dataclasses.replace(pl, **{f.name: (None if getattr(pl, f.name) is None else getattr(pl, f.name)[:1])
                                     for f in dataclasses.fields(pl)})
    point = render(dataclasses.replace(box, point_lights=one), RenderSettings(seed=1, **fast))
    k = soft.stats["direct_light_samples"]
    assert k >= 2 and point.stats["direct_light_samples"] == 1
    # six passes' worth of time at one light sample: 2 pilot passes, then 2 with 2 or 3 with 1
    assert soft.stats["direct_samples"] == 2 + passes_at_equal_cost(6, 2, 2, k) <= 4
    assert point.stats["direct_samples"] == 2 + passes_at_equal_cost(6, 2, 2, 1) == 5
