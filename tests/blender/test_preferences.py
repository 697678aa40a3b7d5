"""Add-on preferences and dependency status (bpy 5.0.1 and Blender 3.4.1)."""
from __future__ import annotations

import logging
from types import SimpleNamespace

import addon_utils
import bpy
import addon
from addon import dependencies, preferences

MISSING = "ercuts_no_such_module"


def test_register_unregister_twice():
    for _ in range(2):
        addon.unregister()
        assert not preferences.ErcutsPreferences.is_registered
        assert not hasattr(bpy.types, "ERCUTS_OT_install_dependencies")
        addon.register()
        assert preferences.ErcutsPreferences.is_registered
        assert hasattr(bpy.types, "ERCUTS_OT_install_dependencies")


def test_preferences_follow_the_package_name():
    """Enabled through Blender's add-on system, the preferences exist under the package's own
    name (``bl_idname = __package__``) and disabling removes them; the accessors fall back to
    defaults when the add-on was only registered (as in this test session)."""
    assert preferences.ErcutsPreferences.bl_idname == addon.__name__
    assert preferences.get() is None and preferences.debug_log() is False
    assert preferences.default_threads() == 0
    addon.unregister()
    try:
        addon_utils.enable(addon.__name__, default_set=True)
        prefs = preferences.get()
        assert prefs is not None and prefs.debug_log is False and prefs.default_threads == 0
        prefs.debug_log = True
        assert logging.getLogger(preferences.LOGGER_NAME).level == logging.DEBUG
        prefs.default_threads = 3
        assert preferences.default_threads() == 3 and preferences.debug_log() is True
        prefs.debug_log = False
        assert logging.getLogger(preferences.LOGGER_NAME).level == logging.WARNING
        addon_utils.disable(addon.__name__, default_set=True)
        assert preferences.get() is None
        assert not preferences.ErcutsPreferences.is_registered
    finally:
        if not preferences.ErcutsPreferences.is_registered:
            addon.register()


def test_status_reports_a_missing_module_cleanly():
    ok, missing = dependencies.status(("numpy", MISSING))
    assert ok.ok and ok.version and ok.location and not ok.error
    assert not missing.ok and missing.version == "" and MISSING in missing.error
    assert missing.error.startswith("ModuleNotFoundError")
    assert dependencies.missing([ok, missing]) == [MISSING]
    assert missing.describe() == f"{MISSING}: {missing.error}"
    assert "Traceback" not in missing.describe()


def test_status_of_the_real_dependencies():
    statuses = dependencies.status()
    assert [s.name for s in statuses] == list(dependencies.MODULES)
    assert dependencies.missing(statuses) == [], [s.describe() for s in statuses]


def test_install_command():
    cmd = dependencies.install_command(["embreex", "scipy"], "/t", python="/py")
    assert cmd[:4] == ["/py", "-m", "pip", "install"]
    assert cmd[cmd.index("--target") + 1] == "/t" and "--no-deps" in cmd
    assert dependencies.REQUIREMENTS["embreex"] in cmd and dependencies.REQUIREMENTS["scipy"] in cmd
    assert not [c for c in cmd if c.startswith("numpy")]  # Blender's numpy is kept


class _Layout:
    """Records labels, operators and properties (no UI in background mode)."""

    def __init__(self):
        self.labels, self.operators, self.props = [], [], []

    def label(self, text="", icon="NONE"):
        self.labels.append((text, icon))

    def operator(self, idname, **kwargs):
        self.operators.append(idname)

    def prop(self, data, name, **kwargs):
        self.props.append(name)

    def box(self):
        return self


def test_draw_shows_missing_dependency_and_the_fix():
    layout = _Layout()
    statuses = dependencies.status(("numpy", "embreex")) + [
        dependencies.DependencyStatus("scipy", error="ModuleNotFoundError: No module named 'scipy'")]
    preferences.draw_dependencies(layout, statuses)
    assert ("scipy: ModuleNotFoundError: No module named 'scipy'", "ERROR") in layout.labels
    assert [icon for _, icon in layout.labels[1:3]] == ["CHECKMARK", "CHECKMARK"]
    assert layout.operators == [preferences.ERCUTS_OT_install_dependencies.bl_idname]
    assert any(dependencies.REQUIREMENTS["scipy"] in text for text, _ in layout.labels)

    complete = _Layout()
    preferences.draw_dependencies(complete, statuses[:2])
    assert complete.operators == [] and all(icon != "ERROR" for _, icon in complete.labels)


def test_preferences_draw_uses_existing_properties():
    layout = _Layout()
    preferences.ErcutsPreferences.draw(SimpleNamespace(layout=layout), bpy.context)
    rna = preferences.ErcutsPreferences.bl_rna.properties
    assert layout.props == ["debug_log", "default_threads"]
    assert all(name in rna for name in layout.props)
    assert len(layout.labels) == 1 + len(dependencies.MODULES)


def test_install_operator_with_nothing_missing_does_nothing():
    """Every dependency imports here, so the operator must not run pip."""
    assert bpy.ops.ercuts.install_dependencies() == {"CANCELLED"}
