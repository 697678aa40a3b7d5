"""Progress, preview and cancellation (api.md) and ``RenderResult.report_dict``.

* progress messages start with the phase name and the fraction rises monotonically over
  the whole render, phases in the algorithm's order;
* preview images have the layout of ``RenderResult.image`` and are rate-limited by
  ``integrators.base.PREVIEW_INTERVAL``;
* cancelling in any phase returns the partial image — never a black one — whose light
  passes still sum to it;
* ``report_dict`` survives ``json.dumps(..., allow_nan=False)``.
"""
from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from ercuts_core import RenderSettings, render
from ercuts_core.film import LIGHT_PASSES
from ercuts_core.sampling import luminance
from ercuts_core.scenes import closed_room, cornell_box

ERCUTS_PHASES = ("BDPT", "Direct light", "ER chains", "VPLs", "Light tree", "Lightcuts")
FAST = dict(integrator="ERCUTS", rough_samples=4, chain_length=20, e1_samples=32)


def _driver():
    """The module of the render clock and its ``PREVIEW_INTERVAL``."""
    import importlib
    return importlib.import_module("ercuts_core.integrators.base")


class Recorder:
    """progress callback that records (fraction, message) and cancels on a chosen phase."""

    def __init__(self, cancel_phase: str | None = None):
        self.calls: list[tuple[float, str]] = []
        self.cancel_phase = cancel_phase

    def __call__(self, fraction: float, message: str):
        self.calls.append((fraction, message))
        return not (self.cancel_phase and message.startswith(self.cancel_phase))

    def phases(self, names) -> list[str]:
        """Phase of every call (the name the message starts with)."""
        out = []
        for _, m in self.calls:
            hit = [n for n in names if m.startswith(n)]
            assert hit, f"message does not start with a phase name: {m!r}"
            out.append(hit[0])
        return out


@pytest.fixture(scope="module")
def ercuts_full():
    rec = Recorder()
    result = render(closed_room(48, 36), RenderSettings(**FAST, seed=2), rec)
    return result, rec


def test_ercuts_progress_names_phases_in_order_and_rises(ercuts_full):
    result, rec = ercuts_full
    assert not result.cancelled
    phases = rec.phases(ERCUTS_PHASES)
    order = [ERCUTS_PHASES.index(p) for p in phases]
    assert order == sorted(order)                          # phases never go back
    assert set(phases) == set(ERCUTS_PHASES)               # every phase reports
    f = np.array([c[0] for c in rec.calls])
    assert (np.diff(f) >= 0).all() and f[0] >= 0 and f[-1] == pytest.approx(1.0)


@pytest.mark.parametrize("integrator", ["PATH", "BDPT"])
def test_path_and_bdpt_progress(integrator):
    rec = Recorder()
    render(cornell_box(24, 18), RenderSettings(integrator=integrator, samples=3, rough_samples=3), rec)
    assert set(rec.phases((integrator,))) == {integrator}
    f = np.array([c[0] for c in rec.calls])
    assert len(f) >= 3 and (np.diff(f) >= 0).all() and f[-1] == pytest.approx(1.0)


@pytest.mark.parametrize("integrator", ["BDPT", "ERCUTS"])
def test_preview_images_and_rate_limit(integrator, monkeypatch):
    """Interval 0: a preview after every BDPT pass (and, for ERCUTS, during the gather);
    a huge interval: exactly one (the first is always sent)."""
    settings = (RenderSettings(**FAST) if integrator == "ERCUTS"
                else RenderSettings(integrator="BDPT", samples=3))
    counts = {}
    for interval in (0.0, 1e9):
        monkeypatch.setattr(_driver(), "PREVIEW_INTERVAL", interval)
        images = []
        result = render(closed_room(24, 18), settings, preview=images.append)
        for img in images:
            assert img.shape == result.image.shape and img.dtype == np.float32
            assert np.isfinite(img).all() and img[..., :3].sum() > 0
        counts[interval] = len(images)
        if integrator == "BDPT" and interval == 0.0:
            np.testing.assert_array_equal(images[-1], result.image)   # the last pass is the result
    assert counts[1e9] == 1
    # ERCUTS: every rough pass, the rough image, the 2 batches (256 + 176 points) of the first
    # gather pass and one image after each further stochastic pass
    passes = RenderSettings().stochastic_passes
    assert counts[0.0] == (3 if integrator == "BDPT" else FAST["rough_samples"] + 1 + 2 + passes - 1)


@pytest.mark.parametrize("phase", ERCUTS_PHASES)
def test_cancel_in_any_phase_keeps_the_image(phase, ercuts_full):
    """Cancelling at the phase's first report keeps an image with (for every phase after the
    first BDPT pass) the energy of the full render: the rough BDPT image, and in Lightcuts
    the gathered pixels plus the rough image elsewhere — never black. Its light passes
    still sum to it."""
    full, _ = ercuts_full
    rec = Recorder(cancel_phase=phase)
    result = render(closed_room(48, 36), RenderSettings(**FAST, seed=2), rec)
    assert result.cancelled
    assert rec.calls[-1][1].startswith(phase)                 # stopped at once
    img = result.image
    assert img.shape == full.image.shape and np.isfinite(img).all()
    ratio = luminance(img[..., :3]).mean() / luminance(full.image[..., :3]).mean()
    # the first BDPT batch is the whole first pass here: a full 1-spp image
    assert 0.8 < ratio < 1.25, ratio
    total = sum(result.aovs[n].astype(np.float64) for n in LIGHT_PASSES)
    np.testing.assert_allclose(total, img[..., :3], rtol=1e-5, atol=1e-6)


def test_cancel_during_lightcuts_mixes_gathered_and_rough_pixels():
    """A cancel inside the first gather batch (256 points) finishes that batch with coarser
    cuts; those pixels come from the gather, the rest from the rough BDPT image."""
    settings = RenderSettings(**FAST, seed=2)
    # cancelled at the first report after the interpolation's planning (a cancel there
    # gathers nothing: test_stopped_by), while the clamp compensation runs before the sweep
    cancelled = render(closed_room(48, 36), settings, Recorder(cancel_phase="Lightcuts: clamp compensation"))
    assert cancelled.stats.get("gather_incomplete") == 1
    cut = cancelled.aovs["cut_size"][..., 0].ravel()
    gathered = cut > 0
    assert 0 < gathered.sum() <= 256 + 48                    # the first batch's pixels only
    rough = render(closed_room(48, 36), settings, Recorder(cancel_phase="ER chains")).image
    same = (cancelled.image == rough).all(axis=2).ravel()
    assert same[~gathered].all() and not same[gathered].all()


def test_lightcut_on_round_stops_refinement():
    """lightcut(on_round=...) returning False stops after the first round with a complete,
    coarser estimate at every point."""
    from ercuts_core.integrators.ercuts.light_tree import build_light_tree
    from ercuts_core.integrators.ercuts.lightcuts import ShadingPoints, lightcut

    rng = np.random.default_rng(0)
    n_vpl, n_pts = 400, 50
    pos = rng.uniform(-1, 1, (n_vpl, 3)) + [0, 0, 3]
    nrm = np.tile([0.0, 0.0, -1.0], (n_vpl, 1))
    inten = rng.uniform(0.1, 1.0, (n_vpl, 3))
    tree = build_light_tree(pos, nrm, inten, seed=0)
    p = np.c_[rng.uniform(-1, 1, (n_pts, 2)), np.zeros(n_pts)]
    n = np.tile([0.0, 0.0, 1.0], (n_pts, 1))
    f = np.full((n_pts, 3), 0.5 / np.pi)
    pts = ShadingPoints(p, n, n.copy(), f, lambda k, wi: f[k], lambda k, q, qn: np.ones(len(k), bool))
    full = lightcut(tree, pos, nrm, inten, pts)
    calls = []
    stopped = lightcut(tree, pos, nrm, inten, pts, on_round=lambda: calls.append(1) or False)
    assert full.rounds > 1 and stopped.rounds == 1 and len(calls) == 1
    assert (stopped.cut_size <= full.cut_size).all() and stopped.cut_size.sum() < full.cut_size.sum()
    assert np.isfinite(stopped.radiance).all() and (stopped.radiance.sum(axis=1) > 0).all()


@pytest.mark.parametrize("integrator", ["PATH", "ERCUTS"])
def test_report_dict_is_json(integrator, ercuts_full):
    if integrator == "ERCUTS":
        result, settings = ercuts_full[0], RenderSettings(**FAST, seed=2)
    else:
        settings = RenderSettings(integrator="PATH", samples=2, seed=7)
        result = render(cornell_box(16, 12), settings)
    result = dataclasses.replace(result, stats={**result.stats, "not_finite": float("nan")})
    d = json.loads(json.dumps(result.report_dict(settings), allow_nan=False))
    assert d["settings"]["integrator"] == integrator and d["seed"] == settings.seed
    assert d["window"]["width"] == result.image.shape[1] and d["cancelled"] is False
    assert d["timings"]["total"] > 0 and d["stats"]["not_finite"] is None
    assert isinstance(d["issues"], list) and isinstance(d["summary"], str)
    if integrator == "ERCUTS":
        assert d["vpl"]["vpls"] > 0 and d["cuts"]["cut_size_mean"] >= 1
        assert set(d["timings"]) >= {"bdpt", "chains", "vpls", "tree", "cuts"}
    else:
        assert d["vpl"] == {} and d["cuts"] == {}
    # settings given as a dict (the add-on's view) work too
    assert json.loads(json.dumps(result.report_dict(settings.__dict__)))["seed"] == settings.seed
