"""The Rendered viewport in a windowed Blender: Debian's 3.4.1 under Xvfb with Mesa's
software OpenGL (tests/gui/viewport_smoke.py does the clicking; this judges its summary).

For the camera view, a free perspective view and a free orthographic view, the pixels Ercuts
draws must cover the geometry Blender itself draws in Solid shading: intersection over
union of the two non-black masks ≥ ``MIN_IOU``. Measured 0.971 / 0.973 / 0.962 (the images
are deterministic: fixed seed, all 4 samples done; the rest is the noise of 4 samples
leaving some pixels dark, and anti-aliased edges in Solid mode); with the field of view
injected 3 % too narrow (lens and orthographic scale) they fell to 0.934 / 0.924 / 0.928,
and an image drawn upside down or in the wrong place would fall far lower. The red wall
must be visible and the log free of tracebacks.

Skipped when there is no ``blender`` or no ``xvfb-run`` (scripts/test.sh installs both on
Debian).
"""
from __future__ import annotations

import json
import os
import shutil
import subprocess
import sysconfig

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
BLENDER, XVFB = shutil.which("blender"), shutil.which("xvfb-run")
pytestmark = pytest.mark.skipif(BLENDER is None or XVFB is None,
                                reason="needs blender and xvfb-run (scripts/test.sh installs them)")
MIN_IOU = 0.95
VIEWS = ("camera", "turned", "ortho")


def test_rendered_viewport_draws_the_scene_where_blender_draws_it(tmp_path):
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([sysconfig.get_paths()["purelib"], ROOT]),
               BLENDER_USER_CONFIG=str(tmp_path / "config"), BLENDER_USER_SCRIPTS=str(tmp_path / "scripts"))
    proc = subprocess.run(
        [XVFB, "-a", "-s", "-screen 0 800x600x24", BLENDER, "--factory-startup",
         os.path.join(ROOT, "blend_scenes", "cornell_box.blend"),
         "--python", os.path.join(ROOT, "tests", "gui", "viewport_smoke.py"), "--", str(tmp_path)],
        env=env, cwd=tmp_path, capture_output=True, text=True, timeout=300)
    log = proc.stdout + proc.stderr
    assert proc.returncode == 0, log[-3000:]
    assert "Traceback" not in log, log[-3000:]
    summary = json.loads((tmp_path / "summary.json").read_text())
    for view in VIEWS:
        s = summary[view]
        assert s["geometry"] > 20000, (view, s)          # the box fills part of the view
        assert s["iou"] >= MIN_IOU, (view, s)
        assert s["red"] > 500, (view, s)
