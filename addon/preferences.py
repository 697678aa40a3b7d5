"""Add-on preferences (Edit > Preferences > Add-ons > Ercuts): dependency status, a debug-log
toggle and the default number of threads.

``bl_idname = __package__`` (shared docs ``blender.md`` §4.2): the package is ``ercuts`` as a
legacy add-on, ``bl_ext.<repo>.ercuts`` as an extension and ``addon`` in the repository, so
the preferences follow whatever name Blender gives the add-on. Blender creates the
preferences only for an add-on enabled through its add-on system; :func:`get` returns None
otherwise (e.g. ``import addon; addon.register()``) and the accessors fall back to defaults.
"""
from __future__ import annotations

import logging

import bpy
from bpy.props import BoolProperty, IntProperty

from . import dependencies

#: Logger of the add-on; :attr:`ErcutsPreferences.debug_log` sets it to DEBUG on stderr.
LOGGER_NAME = "ercuts"


def get(context=None):
    """This add-on's preferences, or None when it was not enabled as an add-on."""
    prefs = getattr(context or bpy.context, "preferences", None)
    addon = prefs.addons.get(__package__) if prefs is not None else None
    return getattr(addon, "preferences", None)


def debug_log(context=None) -> bool:
    """The debug-log toggle (False when there are no preferences)."""
    prefs = get(context)
    return bool(prefs.debug_log) if prefs is not None else False


def default_threads(context=None) -> int:
    """Threads for scenes that leave Ercuts' and Blender's thread counts automatic (0 = all)."""
    prefs = get(context)
    return int(prefs.default_threads) if prefs is not None else 0


def apply_debug_log(enabled: bool) -> None:
    """Send the ``ercuts`` logger's DEBUG records to stderr when ``enabled``, else WARNING+."""
    logger = logging.getLogger(LOGGER_NAME)
    logger.setLevel(logging.DEBUG if enabled else logging.WARNING)
    if enabled and not logger.handlers:
        handler = logging.StreamHandler()
        handler.setFormatter(logging.Formatter("Ercuts %(levelname)s %(name)s: %(message)s"))
        logger.addHandler(handler)


def _debug_log_update(self, context):
    apply_debug_log(self.debug_log)


def draw_dependencies(layout, statuses) -> None:
    """One row per :class:`.dependencies.DependencyStatus`; for missing ones, how to fix it."""
    box = layout.box()
    box.label(text="Dependencies")
    for dep in statuses:
        box.label(text=dep.describe(), icon="CHECKMARK" if dep.ok else "ERROR")
    missing = dependencies.missing(statuses)
    if not missing:
        return
    if dependencies.is_extension():
        box.label(text="The extension's bundled wheels did not load: reinstall the zip built for "
                       "this platform", icon="INFO")
        return
    box.operator(ERCUTS_OT_install_dependencies.bl_idname, icon="IMPORT")
    box.label(text="or, from a terminal:", icon="CONSOLE")
    box.label(text=" ".join(dependencies.install_command(missing, dependencies.user_modules_dir())))


class ERCUTS_OT_install_dependencies(bpy.types.Operator):
    """Install the missing Python modules with pip into your scripts/addons/modules folder"""

    bl_idname = "ercuts.install_dependencies"
    bl_label = "Install Dependencies"
    bl_options = {"REGISTER", "INTERNAL"}

    def execute(self, context):
        missing = [name for name in dependencies.missing(dependencies.status())
                   if name in dependencies.REQUIREMENTS]
        if not missing:
            self.report({"INFO"}, "Ercuts: nothing to install (ercuts_core comes with the add-on)")
            return {"CANCELLED"}
        ok, output = dependencies.install(missing)
        print(f"Ercuts: pip install {' '.join(missing)}:\n{output}")
        if not ok:
            self.report({"ERROR"}, f"Ercuts: installing {', '.join(missing)} failed: "
                                   f"{output.splitlines()[-1] if output else ''} (see the console)")
            return {"CANCELLED"}
        self.report({"INFO"}, f"Ercuts: installed {', '.join(missing)}")
        return {"FINISHED"}


class ErcutsPreferences(bpy.types.AddonPreferences):
    bl_idname = __package__

    debug_log: BoolProperty(
        name="Debug Log",
        description="Print detailed messages of the Ercuts add-on to the console (logger 'ercuts')",
        default=False, update=_debug_log_update,
    )
    default_threads: IntProperty(
        name="Default Threads",
        description=("Threads for scenes whose Ercuts threads and Blender's thread mode are both "
                     "automatic (0 = all cores)"),
        default=0, min=0, soft_max=256,
    )

    def draw(self, context):
        layout = self.layout
        draw_dependencies(layout, dependencies.status())
        layout.prop(self, "debug_log")
        layout.prop(self, "default_threads")


classes = (ERCUTS_OT_install_dependencies, ErcutsPreferences)

_register, _unregister = bpy.utils.register_classes_factory(classes)


def register():
    _register()
    apply_debug_log(debug_log())


def unregister():
    _unregister()
