"""``blender -b`` as a render node runs it (Debian's Blender 3.4.1 in CI), with the add-on
and the core from this checkout on ``PYTHONPATH`` (``scripts/main.sh``'s way):

* the log: one line per phase and at most one ``Fra:`` progress line every
  ``BACKGROUND_STATS_INTERVAL`` seconds (Blender prints one per ``update_stats`` call; a
  6 s Cornell box render printed 729 of them);
* the exit status: reaching the time limit is a normal end (exit 0, "time limit
  reached"); a render interrupted by Ctrl-C (SIGINT, Blender's break flag) fails with the
  reason and writes nothing, through ``blend_scenes/render_blend.py`` and through
  ``-f 1`` (before, render_blend.py saved the partial image);
* render_blend.py's summary names the integrator used.

Skipped only when there is no ``blender`` binary (CI installs Debian's).
"""
from __future__ import annotations

import os
import re
import shutil
import signal
import subprocess
import sysconfig
import threading

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
BLENDER = shutil.which("blender")
pytestmark = pytest.mark.skipif(BLENDER is None, reason="no blender binary (CI installs Debian's blender)")
SCENE = os.path.join(ROOT, "blend_scenes", "cornell_box.blend")
RENDER_BLEND = os.path.join(ROOT, "blend_scenes", "render_blend.py")
#: The add-on's interval between two background stats lines (addon.engine).
INTERVAL = 5.0


def env() -> dict:
    e = dict(os.environ)
    e["PYTHONPATH"] = os.pathsep.join([sysconfig.get_paths()["purelib"], ROOT])
    return e


def render_blend(out, *options, timeout=300) -> subprocess.CompletedProcess:
    args = [BLENDER, "-b", "--factory-startup", "--python", RENDER_BLEND, "--", SCENE, "-o", str(out),
            *options]
    return subprocess.run(args, env=env(), capture_output=True, text=True, timeout=timeout)


def interrupt_when(args, marker: str, cwd, timeout=120) -> tuple[int, str, str]:
    """Run ``args``, send SIGINT once stdout shows ``marker``; (status, stdout, stderr)."""
    proc = subprocess.Popen(args, env=env(), cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)
    lines, seen = [], threading.Event()

    def read():
        for line in proc.stdout:
            lines.append(line)
            if marker in line:
                seen.set()

    reader = threading.Thread(target=read, daemon=True)
    reader.start()
    try:
        assert seen.wait(timeout), "".join(lines)
        proc.send_signal(signal.SIGINT)
        err = proc.stderr.read()
        proc.wait(timeout)
    finally:
        if proc.poll() is None:
            proc.kill()
    reader.join(10)
    return proc.returncode, "".join(lines), err


def _seconds(fra_line: str) -> float:
    minutes, seconds = re.search(r"Time:(\d+):([\d.]+)", fra_line).groups()
    return 60 * int(minutes) + float(seconds)


def test_log_has_a_line_per_phase_and_rare_progress_lines(tmp_path):
    """ERCUTS with a time limit: every phase once, few ``Fra:`` lines, a normal end."""
    proc = render_blend(tmp_path / "cb", "--resolution", "96", "72", "--time-limit", "10")
    out = proc.stdout
    assert proc.returncode == 0, out[-3000:] + proc.stderr[-3000:]
    phases = [line for line in out.splitlines() if line.startswith("Ercuts: ViewLayer | ")]
    assert len(phases) >= 5 and len({p.split(" | ")[1] for p in phases}) == len(phases), phases
    fra = [line for line in out.splitlines() if line.startswith("Fra:")]
    # 'Exporting scene', the final summary, and progress lines at least INTERVAL apart.
    assert "Exporting scene" in fra[0] and "total" in fra[-1], fra
    progress = [_seconds(line) for line in fra[1:-1]]
    assert len(fra) <= 2 + _seconds(fra[-1]) / INTERVAL, fra
    assert all(b - a >= INTERVAL - 0.5 for a, b in zip(progress, progress[1:])), fra
    assert "CANCELLED" not in out and "cancelled" not in out.lower()
    assert (tmp_path / "cb.exr").is_file() and (tmp_path / "cb.png").is_file()


def test_summary_names_the_integrator(tmp_path):
    proc = render_blend(tmp_path / "bdpt", "--resolution", "32", "24", "--integrator", "BDPT", "--samples", "1")
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    assert "with ERCUTS (integrator BDPT) in" in proc.stdout


def test_interrupted_render_blend_fails_and_writes_nothing(tmp_path):
    args = [BLENDER, "-b", "--factory-startup", "--python", RENDER_BLEND, "--", SCENE,
            "-o", str(tmp_path / "out" / "cb"), "--resolution", "64", "48", "--integrator", "PATH",
            "--samples", "100000"]
    status, out, err = interrupt_when(args, "Ercuts: ViewLayer | PATH", tmp_path)
    assert status != 0
    assert "render cancelled by Blender's break signal" in err, out[-2000:] + err[-2000:]
    assert os.listdir(tmp_path / "out") == []


def test_interrupted_frame_fails_with_the_reason(tmp_path):
    """``blender -b scene.blend -E ERCUTS -f 1`` and Ctrl-C: Blender writes no frame and
    exits 1 by itself; the engine says why."""
    shutil.copy2(SCENE, tmp_path / "scene.blend")
    setup = ("import addon, bpy; addon.register(); s = bpy.context.scene; "
             "s.render.resolution_x, s.render.resolution_y = 64, 48; s.render.resolution_percentage = 100; "
             "s.ercuts.integrator = 'PATH'; s.ercuts.samples = 100000")
    args = [BLENDER, "-b", str(tmp_path / "scene.blend"), "--python-expr", setup, "-E", "ERCUTS",
            "-o", "//out/frame_####", "-F", "OPEN_EXR", "-f", "1"]
    status, out, err = interrupt_when(args, "Ercuts: ViewLayer | PATH", tmp_path)
    assert status != 0
    assert "render cancelled by Blender's break signal" in out + err, out[-2000:] + err[-2000:]
    assert not (tmp_path / "out").exists() or os.listdir(tmp_path / "out") == []
