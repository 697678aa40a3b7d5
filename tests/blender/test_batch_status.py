"""How a background render (``blender -b``, the bpy module) ends: reaching the time limit
is a normal end (labelled so, not "CANCELLED"); a render stopped by Blender's break flag
(Ctrl-C in ``blender -b``; here the engine's ``_should_stop`` hook stands in for
``test_break``) is an error: ``bpy.ops.render.render`` raises with the reason and no file
is written. In the UI a cancel keeps the partial image (the ``interactive`` tests in
test_render.py, test_faults.py and test_engine_ux.py). ``tests/test_blender_batch.py``
checks the same with Debian's ``blender`` binary and a real SIGINT."""
from __future__ import annotations

import bpy
import pytest

import blender_helpers as h
from addon import engine as engine_module
from addon.engine import ErcutsRenderEngine


def _scene(samples=200):
    h.camera(location=(0, 0, 5))
    h.plane("Floor", size=20, material=h.diffuse("Floor"))
    h.light("POINT", location=(0, 0, 3), energy=200)
    s = h.setup_render(32, 24, samples=samples)
    s.ercuts.batch_rays = 1024          # several progress polls per pass
    return s


@pytest.mark.parametrize("when", ["export", "render"])
def test_cancel_in_background_is_an_error_without_a_file(tmp_path, monkeypatch, when):
    polls = []

    def should_stop(self):
        polls.append(1)
        return when == "export" or len(polls) >= 3

    monkeypatch.setattr(ErcutsRenderEngine, "_should_stop", should_stop)
    _scene()
    assert bpy.app.background
    with pytest.raises(RuntimeError, match="render cancelled by Blender's break signal"):
        h.render_exr(tmp_path / "cancelled.exr")
    assert not (tmp_path / "cancelled.exr").exists()
    if when == "render":
        assert engine_module.last_render["stopped_by"] == "cancel"


def test_time_limit_is_a_normal_end(tmp_path, capsys):
    s = _scene(samples=100000)
    s.ercuts.time_limit = 1.0
    img = h.render_exr(tmp_path / "limited.exr")
    info = engine_module.last_render
    assert info["cancelled"] is True and info["stopped_by"] == "time_limit"
    assert "time limit reached" in info["summary"] and "CANCELLED" not in info["summary"]
    out = capsys.readouterr().out
    assert "Ercuts: time limit of 1 s reached" in out and "stopped early" not in out
    assert img[..., :3].max() > 0
