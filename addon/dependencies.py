"""The add-on's third-party Python modules: where they come from, whether they import, and
how to install the missing ones.

Where each runtime gets them (shared docs ``blender.md`` §4.3):

* **Blender ≥ 4.2, extension zip**: the wheels listed in ``blender_manifest.toml``
  (``ercuts_core``, embreex, scipy, OpenEXR, numba + llvmlite), which Blender installs into its extensions'
  shared site-packages; numpy ships with Blender.
* **Blender 3.x, legacy zip**: ``ercuts_core`` is vendored in ``<package>/vendor`` (see
  :func:`use_vendored_core`); numpy, embreex, scipy and OpenEXR come from Blender's Python,
  from ``PYTHONPATH`` (Debian's Blender honours it), or from the user's
  ``scripts/addons/modules`` folder, which Blender puts on ``sys.path`` and where
  :func:`install_command` makes pip install them (the preferences' *Install Dependencies*).
* **Development** (``import addon`` from the repository): the project's ``.venv``.

Nothing here imports numpy or the core at module level, so the add-on registers without them.
"""
from __future__ import annotations

import importlib
import os
import sys
from dataclasses import dataclass

#: Modules the renderer imports, in the order they are reported.
MODULES = ("numpy", "embreex", "scipy", "OpenEXR", "numba", "ercuts_core")

#: pip requirement per module, for a Blender whose Python lacks it (Python 3.10/3.11; numpy < 2
#: like bpy 5.0.1; scipy < 1.14 still supports the older numpy of Blender 3.x builds).
REQUIREMENTS = {
    "numpy": "numpy>=1.24,<2",
    "embreex": "embreex==4.4.0.post1",
    "scipy": "scipy>=1.11,<1.14",
    "OpenEXR": "OpenEXR>=3.2,<4",
    # optional: the gather's compiled kernels (the core falls back to numpy and warns)
    "numba": "numba==0.68.1 llvmlite==0.50.0",
}

#: Distribution names where they differ from the module name (for the version lookup).
_DISTRIBUTIONS = {"ercuts_core": "ercuts-core"}

#: Folder of the vendored core in the legacy zip (``<package>/vendor/ercuts_core``).
VENDOR_DIR = os.path.join(os.path.dirname(os.path.abspath(__file__)), "vendor")


@dataclass(frozen=True)
class DependencyStatus:
    """One module's state: ``version`` and ``location`` when it imports, else ``error``."""

    name: str
    version: str = ""
    location: str = ""
    error: str = ""

    @property
    def ok(self) -> bool:
        return not self.error

    def describe(self) -> str:
        """One line for the preferences or the console."""
        if self.ok:
            return f"{self.name} {self.version} ({self.location})"
        return f"{self.name}: {self.error}"


def use_vendored_core() -> None:
    """Put ``<package>/vendor`` first on ``sys.path`` when it exists (legacy zip), so that
    ``import ercuts_core`` finds the core built with this add-on. No-op otherwise."""
    if os.path.isdir(VENDOR_DIR) and VENDOR_DIR not in sys.path:
        sys.path.insert(0, VENDOR_DIR)


def _version(name: str, module) -> str:
    version = getattr(module, "__version__", None)
    if version:
        return str(version)
    try:
        from importlib import metadata

        return metadata.version(_DISTRIBUTIONS.get(name, name))
    except Exception:  # noqa: BLE001 - PackageNotFoundError, or broken metadata
        return "(no version)"


def check(name: str) -> DependencyStatus:
    """Import ``name`` and report its version and folder, or the error (never raises).

    Every exception counts, not only ImportError: a binary module built for another numpy or
    Python fails with AttributeError/OSError/RuntimeError at import.
    """
    try:
        module = importlib.import_module(name)
    except Exception as exc:  # noqa: BLE001 - reported, not raised
        return DependencyStatus(name, error=f"{type(exc).__name__}: {exc}")
    path = getattr(module, "__file__", None) or ""
    if os.path.basename(path).startswith("__init__."):
        path = os.path.dirname(path)
    return DependencyStatus(name, version=_version(name, module), location=os.path.dirname(path))


def status(modules=MODULES) -> list[DependencyStatus]:
    """:func:`check` of every module in ``modules`` (embreex is preloaded the safe way first)."""
    from . import compat

    compat.preload_embreex()
    return [check(name) for name in modules]


def missing(statuses) -> list[str]:
    """Names of the modules in ``statuses`` that did not import."""
    return [s.name for s in statuses if not s.ok]


def is_extension() -> bool:
    """True when the add-on runs as a Blender ≥ 4.2 extension (module ``bl_ext.<repo>.<id>``),
    whose dependencies come from its bundled wheels rather than from pip."""
    return (__package__ or "").startswith("bl_ext.")


def user_modules_dir() -> str:
    """The user's ``scripts/addons/modules`` folder, created.

    Blender puts it on ``sys.path`` at startup when it exists (``bpy.utils.refresh_script_paths``
    adds ``<addons>/modules``; verified on 3.4.1 and 5.0.1), also under ``--factory-startup``,
    which drops ``scripts/modules``.
    """
    import bpy

    return bpy.utils.user_resource("SCRIPTS", path=os.path.join("addons", "modules"), create=True)


def install_command(names, target: str, python: str | None = None) -> list[str]:
    """The pip command installing the modules ``names`` into ``target``.

    ``--target`` keeps Blender's own Python untouched (and is allowed on Debian's externally
    managed Python); ``--python-version`` and binary wheels make it right for Blender's
    Python even when ``python`` is another interpreter; ``--no-deps`` keeps Blender's numpy
    (numpy is installed only when it is itself missing).
    """
    reqs = [req for n in names if n in REQUIREMENTS for req in REQUIREMENTS[n].split()]
    version = f"{sys.version_info.major}.{sys.version_info.minor}"
    return [python or sys.executable, "-m", "pip", "install", "--target", target, "--upgrade",
            "--no-deps", "--only-binary=:all:", "--python-version", version, *reqs]


def install(names, target: str | None = None, timeout: float = 900.0) -> tuple[bool, str]:
    """Run :func:`install_command` for ``names``; (success, last lines of pip's output).

    The target is added to ``sys.path`` afterwards, so a render can start without a restart.
    """
    import subprocess

    target = target or user_modules_dir()
    cmd = install_command(names, target)
    try:
        proc = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout)
    except (OSError, subprocess.TimeoutExpired) as exc:
        return False, f"{type(exc).__name__}: {exc}"
    output = "\n".join((proc.stdout + proc.stderr).strip().splitlines()[-5:])
    if proc.returncode != 0:
        return False, output or f"pip exited with status {proc.returncode}"
    if target not in sys.path:
        sys.path.append(target)
    importlib.invalidate_caches()
    return True, output
