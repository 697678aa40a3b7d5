"""The newcomer's scripts (issue 18): ``scripts/main.sh`` renders any ``.blend`` given as its
first argument, and ``scripts/setup_env.sh`` says what it installs and shows pip's progress.

Both run in a copy of the repository (:mod:`repo_copy`), main.sh with ``ERCUTS_QUICK=1``
(renders stop after 3 s; README).
"""
from __future__ import annotations

import os
import re
import shutil
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
    assert re.search(r"cornell_box\.blend with ERCUTS \(integrator PATH\) in [\d.]+ s", proc.stdout)
    assert (out / "cornell_box.exr").stat().st_size > 10_000


def test_main_sh_refuses_a_missing_scene(repo, tmp_path):
    proc = subprocess.run(["bash", "scripts/main.sh", "blend_scenes/no_such.blend"], cwd=repo,
                          env=_env(ERCUTS_OUT=str(tmp_path)), capture_output=True, text=True,
                          timeout=120)
    assert proc.returncode == 2
    assert "main.sh: no such scene" in proc.stderr and "no_such.blend" in proc.stderr
    assert not os.listdir(tmp_path)


@pytest.mark.slow
@pytest.mark.skipif(shutil.which("python3.11") is None, reason="needs python3.11")
def test_setup_env_says_what_it_installs(tmp_path):
    """A first set-up prints what it installs and pip's own progress (it used to print
    nothing for about a minute); a second run, with requirements.txt unchanged, nothing.
    A fresh venv with one small pinned requirement (tqdm, from requirements.txt)."""
    (tmp_path / "scripts").mkdir()
    shutil.copy2(os.path.join(repo_copy.ROOT, "scripts", "setup_env.sh"), tmp_path / "scripts")
    with open(os.path.join(repo_copy.ROOT, "requirements.txt")) as fh:
        (pin,) = [line.strip() for line in fh if line.startswith("tqdm==")]
    (tmp_path / "requirements.txt").write_text(f"# one package\n{pin}\n")
    cmd = ["bash", str(tmp_path / "scripts" / "setup_env.sh")]
    first = subprocess.run(cmd, env=_env(), capture_output=True, text=True, timeout=600)
    assert first.returncode == 0, first.stdout + first.stderr
    assert "setup: installing requirements.txt (1 packages) into .venv" in first.stdout
    assert "first run ≈ 1 min" in first.stdout
    assert re.search(r"^Collecting tqdm", first.stdout, re.MULTILINE), first.stdout
    assert "Successfully installed tqdm" in first.stdout
    assert first.stdout.rstrip().endswith("setup: .venv ready")
    assert (tmp_path / ".venv" / "bin" / "python").is_file()
    again = subprocess.run(cmd, env=_env(), capture_output=True, text=True, timeout=120)
    assert again.returncode == 0 and again.stdout == ""
