"""One-line error messages for the UI (the render's report, the viewport's status text).

Known errors (an export error naming the Blender object, a scene error from the core's
validation) pass through as they are; a missing dependency says what to install; anything
else is named with a pointer to the console, where the traceback goes.
"""
from __future__ import annotations


def error_message(exc: Exception) -> str:
    """The message shown to the user for ``exc``."""
    known = ()
    try:  # both import numpy: without it, fall through to the dependency message
        from .export import ExportError
        known += (ExportError,)
        from ercuts_core.validate import SceneError
        known += (SceneError,)
        from ercuts_core.cluster import ClusterError
        known += (ClusterError,)
    except ImportError:
        pass
    if isinstance(exc, known):
        return str(exc)
    missing = getattr(exc, "name", None) or ""
    if isinstance(exc, ModuleNotFoundError) and missing.split(".")[0] in {
            "numpy", "embreex", "ercuts_core"}:
        return (f"cannot load the Ercuts core ({exc}); numpy, embreex and ercuts_core "
                "must be importable by Blender's Python")
    return f"{type(exc).__name__}: {exc} (see the console for details)"
