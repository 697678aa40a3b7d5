"""Ercuts: a Blender render engine backed by the pure-Python ``ercuts_core``.

The add-on turns Blender's evaluated scene into an ``ercuts_core.SceneDescription``
(:mod:`.export`), renders it with ``ercuts_core.render`` and writes the image into
Blender's render result (:mod:`.engine`, :mod:`.framebuffer`). Settings live in
``scene.ercuts`` (:mod:`.properties`), panels in :mod:`.ui`, and every Blender-version
difference in :mod:`.compat`. Only relative imports are used inside the package, so it
can be installed under any name; the core is imported as the top-level package
``ercuts_core`` (with numpy and embreex) only when a render starts, so the add-on
registers even where those are missing and then reports it when rendering; the add-on
preferences (:mod:`.preferences`) show which dependency is missing and how to install it.
The packages users install are built by ``scripts/build_addon.py`` (an extension zip for
Blender ≥ 4.2 with ``blender_manifest.toml``, and a legacy zip for 3.x).
"""

bl_info = {
    "name": "Ercuts",
    "author": "Ercuts project",
    "version": (0, 1, 0),
    "blender": (3, 4, 0),
    "location": "Properties > Render > Render Engine > Ercuts",
    "description": "Render engine for scenes lit mostly by indirect light (ER chains + VPL lightcuts, BDPT, path tracing)",
    "category": "Render",
}

from . import compat, dependencies  # noqa: E402

dependencies.use_vendored_core()  # legacy zip: the core is in <package>/vendor
compat.preload_embreex()  # before anything imports the core (see compat.preload_embreex)

from . import denoise, engine, preferences, presets, properties, ui  # noqa: E402

#: Registered in this order, unregistered in reverse (add a module with register() here).
_modules = (
    preferences,
    properties,
    engine,
    presets,
    denoise,
    ui,
)


def register():
    for module in _modules:
        module.register()


def unregister():
    from . import viewport

    viewport.stop_all()
    for module in reversed(_modules):
        module.unregister()
