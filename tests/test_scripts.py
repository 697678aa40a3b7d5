"""The newcomer's scripts (issue 18): ``scripts/main.sh`` renders any ``.blend`` given as its
first argument. It runs in a copy of the repository (:mod:`repo_copy`) with ``ERCUTS_QUICK=1``
(renders stop after 3 s; README).
"""
from __future__ import annotations

import os
import re
import subprocess

import pytest

import repo_copy


@pytest.fixture(scope="module")
def repo(tmp_path_factory):
    return repo_copy.make_copy(str(tmp_path_factory.mktemp("scripts") / "repo"))


def _env(**extra) -> dict:
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "ERCUTS_OUT")}
    env.update(extra)
    return env


def test_main_sh_renders_the_scene_given_first(repo, tmp_path):
    """``bash scripts/main.sh blend_scenes/cornell_box.blend --integrator PATH`` writes
    ``cornell_box.exr`` and ``.png`` (it used to fail: 'unrecognized arguments')."""
    out = tmp_path / "out"
    proc = subprocess.run(["bash", "scripts/main.sh", "blend_scenes/cornell_box.blend",
                           "--integrator", "PATH"], cwd=repo, env=_env(ERCUTS_QUICK="1", ERCUTS_OUT=str(out)),
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    assert sorted(os.listdir(out)) == ["cornell_box.exr", "cornell_box.png"]
    assert re.search(r"cornell_box\.blend with ERCUTS in [\d.]+ s", proc.stdout)
    assert (out / "cornell_box.exr").stat().st_size > 10_000


def test_main_sh_refuses_a_missing_scene(repo, tmp_path):
    proc = subprocess.run(["bash", "scripts/main.sh", "blend_scenes/no_such.blend"], cwd=repo,
                          env=_env(ERCUTS_OUT=str(tmp_path)), capture_output=True, text=True,
                          timeout=120)
    assert proc.returncode == 2
    assert "main.sh: no such scene" in proc.stderr and "no_such.blend" in proc.stderr
    assert not os.listdir(tmp_path)

