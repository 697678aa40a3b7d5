"""pytest setup for the add-on tests, run with the ``bpy`` module (Blender as a module).

``bpy`` is imported once per process (it cannot be reloaded), the add-on is
registered once per session, and every test starts from an empty factory scene
(``read_factory_settings(use_empty=True)`` keeps registered classes).
"""
from __future__ import annotations

import os
import sys

import pytest

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(os.path.dirname(HERE))
for path in (ROOT, HERE):
    if path not in sys.path:
        sys.path.insert(0, path)

bpy = pytest.importorskip("bpy")  # before anything that imports mathutils/gpu

import addon  # noqa: E402


def pytest_configure(config):
    config.addinivalue_line("markers", "slow: slow renders (Cycles agreement); run with -m slow")


@pytest.fixture(scope="session", autouse=True)
def ercuts_addon():
    """The add-on, registered for the whole session."""
    addon.register()
    yield addon
    addon.unregister()


@pytest.fixture(autouse=True)
def fresh_scene():
    """An empty scene per test."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    yield bpy.context.scene


@pytest.fixture
def interactive(monkeypatch):
    """Render as in Blender's UI, where a cancelled render (Esc) keeps its partial image;
    in background mode, where these tests run, a cancel is an error (``addon.engine``)."""
    from addon.engine import ErcutsRenderEngine

    monkeypatch.setattr(ErcutsRenderEngine, "_is_batch", lambda self: False)
