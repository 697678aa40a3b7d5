"""``ERCUTS_QUICK=1`` (README: the README test's smoke runs of the documented commands): the
core's command line caps every render's time limit at 3 s, and ``benchmarks/report.py`` plans
a one-seed, 1 s run under ``out/quick/`` (the add-on's cap: ``tests/blender/test_quick.py``)."""
from __future__ import annotations

import os
import re
import subprocess
import sys

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


@pytest.mark.parametrize("value, limit, expected", [
    (None, 0.0, 0.0), ("0", 30.0, 30.0), ("1", 0.0, 3.0), ("1", 30.0, 3.0), ("1", 2.0, 2.0)])
def test_quick_caps_the_core_command_line(monkeypatch, value, limit, expected):
    from ercuts_core.settings import quick_time_limit as _time_limit

    if value is None:
        monkeypatch.delenv("ERCUTS_QUICK", raising=False)
    else:
        monkeypatch.setenv("ERCUTS_QUICK", value)
    assert _time_limit(limit) == expected


def test_quick_benchmarks_leave_the_stored_results_alone():
    """``ERCUTS_QUICK=1 report.py`` plans one seed at 1 s (9 scenes × 5 engines) with runs and
    report under out/quick/ (the dry run writes nothing)."""
    env = dict(os.environ, ERCUTS_QUICK="1")
    proc = subprocess.run([sys.executable, os.path.join(ROOT, "benchmarks", "report.py"), "--dry-run"],
                          cwd=ROOT, env=env, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert os.path.join("out", "quick", "benchmarks") in proc.stdout
    assert re.search(r"report: 45 renders planned", proc.stdout), proc.stdout   # 9 scenes × 5 engines
