"""``ERCUTS_QUICK=1`` (README: smoke runs of the documented commands) caps the time limit of
every render the add-on starts at 3 s; unset, empty or 0 it changes nothing."""
from __future__ import annotations

import pytest



@pytest.mark.parametrize("value, limit, expected", [
    (None, 0.0, 0.0), ("0", 10.0, 10.0), ("", 10.0, 10.0),
    ("1", 0.0, 3.0), ("1", 10.0, 3.0), ("1", 1.5, 1.5),
])
def test_quick_caps_the_time_limit(fresh_scene, monkeypatch, value, limit, expected):
    if value is None:
        monkeypatch.delenv("ERCUTS_QUICK", raising=False)
    else:
        monkeypatch.setenv("ERCUTS_QUICK", value)
    fresh_scene.ercuts.time_limit = limit
    assert fresh_scene.ercuts.to_core().time_limit == pytest.approx(expected)
    from ercuts_core.settings import QUICK_TIME_LIMIT

    assert QUICK_TIME_LIMIT == 3.0
