"""Why a render stopped early (``RenderResult.stopped_by``): a used-up time budget is a
normal end ('time_limit', summary "time limit reached"); a progress callback returning
False is an interruption ('cancel', summary "CANCELLED"). Both keep ``cancelled`` True
(the image is what the time allowed). Before, both were "CANCELLED", so a batch render
that met its time limit looked interrupted and one that was interrupted looked finished."""
from __future__ import annotations

import json

import pytest

from ercuts_core import RenderSettings, render
from ercuts_core.scenes import closed_room, cornell_box

FAST_ERCUTS = dict(integrator="ERCUTS", samples=2, chain_length=10, e1_samples=16, direct_samples=2)


@pytest.mark.parametrize("integrator", ["PATH", "BDPT"])
def test_time_limit_is_not_a_cancel(integrator):
    r = render(cornell_box(32, 24), RenderSettings(integrator=integrator, samples=100000, rough_samples=100000, time_limit=0.5))
    assert r.cancelled and r.stopped_by == "time_limit"
    assert "time limit reached" in r.summary() and "CANCELLED" not in r.summary()
    assert json.loads(json.dumps(r.report_dict()))["stopped_by"] == "time_limit"


@pytest.mark.parametrize("integrator", ["PATH", "ERCUTS"])
def test_progress_false_is_a_cancel(integrator):
    calls = []

    def progress(fraction, message):
        calls.append(message)
        return len(calls) < 3

    settings = RenderSettings(**FAST_ERCUTS) if integrator == "ERCUTS" else \
        RenderSettings(integrator="PATH", samples=50)
    r = render(closed_room(24, 18), settings, progress)
    assert r.cancelled and r.stopped_by == "cancel"
    assert "CANCELLED" in r.summary() and "time limit" not in r.summary()


def test_cancel_in_the_gather_with_a_time_limit_reads_cancel():
    """Interrupted in the ERCUTS gather (Lightcuts) with a generous time limit."""
    r = render(closed_room(24, 18), RenderSettings(**FAST_ERCUTS, time_limit=60.0),
               lambda f, m: not m.startswith("Lightcuts"))
    assert r.stopped_by == "cancel" and r.stats.get("gather_incomplete") == 1


def test_complete_render_stopped_by_nothing():
    r = render(cornell_box(16, 12), RenderSettings(integrator="PATH", samples=2))
    assert not r.cancelled and r.stopped_by is None
    assert "CANCELLED" not in r.summary() and "time limit" not in r.summary()


def test_time_running_out_in_the_gather_is_the_time_limit():
    """The ERCUTS gather stops itself when no time is left (``gather_incomplete``) without
    the driver's deadline check: still the time limit, not a cancel (a 10 s Blender render
    of the Cornell box ended "cancelled" that way). The progress callback sleeps past the
    deadline at the gather's first message, so the time surely runs out there."""
    import time

    limit = 3.0
    t0 = time.perf_counter()

    def progress(fraction, message):
        if message.startswith("Lightcuts"):
            time.sleep(max(0.0, t0 + limit + 0.05 - time.perf_counter()))

    r = render(closed_room(24, 18), RenderSettings(**FAST_ERCUTS, time_limit=limit), progress)
    assert r.stats.get("gather_incomplete") == 1
    assert r.cancelled and r.stopped_by == "time_limit"
