"""Build the Ercuts add-on packages that users install into Blender.

    .venv/bin/python scripts/build_addon.py                       # everything -> dist/
    .venv/bin/python scripts/build_addon.py --platforms linux-x64 --python 3.11

Writes to ``dist/`` (shared docs ``blender.md`` §4):

* ``ercuts-<version>-<platform>.zip`` (``linux_x64``, ``windows_x64``): the extension for
  Blender ≥ 4.2 — the add-on, ``blender_manifest.toml`` and ``wheels/``: the pure-Python core
  (``ercuts_core``, built from ``pyproject.toml``) and embreex, scipy, OpenEXR, numba and llvmlite for
  CPython 3.11 (Blender 4.2–5.0) and 3.13 (Blender 5.1+), unmodified from PyPI. numpy is not
  bundled: Blender ships it. Built and then validated by Blender's own extension tool
  (``bl_pkg/cli/blender_ext.py`` from the bpy wheel, or ``--blender-ext``).
* ``ercuts-<version>-legacy.zip``: the same add-on as a legacy add-on (``bl_info``) for
  Blender 3.x, one top-level folder ``ercuts/`` with the core vendored in ``ercuts/vendor/``;
  numpy, embreex, scipy, OpenEXR and numba come from Blender's Python (see the README).

Wheels are cached in ``build/wheels/`` (an offline rebuild reuses them); staging happens in
``build/addon/``. The versions in ``bl_info``, the manifest and ``pyproject.toml`` must agree.
"""
from __future__ import annotations

import argparse
import ast
import glob
import importlib.util
import os
import shutil
import subprocess
import sys
import tomllib
import zipfile

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
ADDON = os.path.join(ROOT, "addon")
PACKAGE = "ercuts"  # the installed module name (legacy folder; the extension id is the same)

#: Blender platform -> pip ``--platform`` tags to try (pip takes the first that has a wheel).
PLATFORM_TAGS = {
    "linux-x64": ("manylinux_2_28_x86_64", "manylinux_2_17_x86_64", "manylinux2014_x86_64"),
    "windows-x64": ("win_amd64",),
}
#: CPython versions of Blender: 3.11 in Blender 4.2-5.0, 3.13 from Blender 5.1.
PYTHONS = ("3.11", "3.13")
#: Bundled third-party wheels (pins from requirements.txt); numpy ships with Blender. numba and
#: llvmlite (≈ 4 + 60 MB per Python and platform) run the gather's compiled kernels
#: (``ercuts_core.kernels``; without them the core falls back to numpy and warns).
BUNDLED = ("embreex", "scipy", "OpenEXR", "numba", "llvmlite")
#: Pins that differ per Python (requirements.txt's scipy 1.13.1 has no CPython 3.13 wheel).
PYTHON_PINS = {"3.13": {"scipy": "scipy==1.14.1"}}
#: Files never packaged.
IGNORE = shutil.ignore_patterns("__pycache__", "*.pyc", "*.blend1")


def log(message: str) -> None:
    print(f"build_addon: {message}", flush=True)


def run(cmd, **kwargs) -> subprocess.CompletedProcess:
    """Run ``cmd``; on failure exit with its output."""
    proc = subprocess.run(cmd, capture_output=True, text=True, **kwargs)
    if proc.returncode != 0:
        sys.exit(f"build_addon: command failed ({proc.returncode}): {' '.join(cmd)}\n"
                 f"{proc.stdout}{proc.stderr}")
    return proc


# --------------------------------------------------------------------------- versions and pins

def versions() -> dict[str, str]:
    """The version in ``pyproject.toml``, ``blender_manifest.toml`` and ``bl_info``."""
    with open(os.path.join(ROOT, "pyproject.toml"), "rb") as f:
        pyproject = tomllib.load(f)["project"]["version"]
    with open(os.path.join(ADDON, "blender_manifest.toml"), "rb") as f:
        manifest = tomllib.load(f)["version"]
    with open(os.path.join(ADDON, "__init__.py"), encoding="utf-8") as f:
        tree = ast.parse(f.read())
    bl_info = next(ast.literal_eval(node.value) for node in tree.body if isinstance(node, ast.Assign)
                   and any(getattr(t, "id", None) == "bl_info" for t in node.targets))
    return {"pyproject.toml": pyproject, "blender_manifest.toml": manifest,
            "bl_info": ".".join(str(v) for v in bl_info["version"])}


def check_versions() -> str:
    """The common version; exits when the three sources disagree."""
    found = versions()
    if len(set(found.values())) != 1:
        sys.exit(f"build_addon: versions disagree: {found}")
    return found["pyproject.toml"]


def requirement_pins(python: str) -> list[str]:
    """``name==version`` of every bundled module for ``python`` (requirements.txt + PYTHON_PINS)."""
    pins = {}
    with open(os.path.join(ROOT, "requirements.txt"), encoding="utf-8") as f:
        for line in f:
            line = line.split("#")[0].strip()
            if "==" in line:
                pins[line.split("==")[0].strip().lower()] = line
    pins.update({k.lower(): v for k, v in PYTHON_PINS.get(python, {}).items()})
    missing = [name for name in BUNDLED if name.lower() not in pins]
    if missing:
        sys.exit(f"build_addon: no pin for {missing} in requirements.txt")
    return [pins[name.lower()] for name in BUNDLED]


# --------------------------------------------------------------------------- wheels

def build_core_wheel(dest: str, staging: str) -> str:
    """Build ``ercuts_core-<version>-py3-none-any.whl`` from a clean copy of the core."""
    src = os.path.join(staging, "core_src")
    shutil.rmtree(src, ignore_errors=True)
    os.makedirs(src)
    shutil.copy2(os.path.join(ROOT, "pyproject.toml"), src)
    shutil.copytree(os.path.join(ROOT, "ercuts_core"), os.path.join(src, "ercuts_core"), ignore=IGNORE)
    shutil.rmtree(dest, ignore_errors=True)
    os.makedirs(dest)
    run([sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", "-w", dest, src])
    found = glob.glob(os.path.join(dest, "ercuts_core-*-py3-none-any.whl"))
    if len(found) != 1:
        sys.exit(f"build_addon: expected one core wheel in {dest}, found {found}")
    return found[0]


def download_wheels(platform: str, python: str, cache: str) -> list[str]:
    """The bundled wheels for one Blender platform and CPython version, from ``cache`` when
    they are there, else from PyPI (``pip download``, binary wheels only, no dependencies)."""
    dest = os.path.join(cache, f"{platform}-cp{python.replace('.', '')}")
    os.makedirs(dest, exist_ok=True)
    pins = requirement_pins(python)
    cmd = [sys.executable, "-m", "pip", "download", "-q", "--no-deps", "--only-binary=:all:",
           "--python-version", python, "--implementation", "cp", "--dest", dest]
    for tag in PLATFORM_TAGS[platform]:
        cmd += ["--platform", tag]
    offline = subprocess.run(cmd + ["--no-index", "--find-links", dest] + pins, capture_output=True)
    if offline.returncode != 0:
        log(f"downloading {', '.join(pins)} for {platform}, Python {python}")
        run(cmd + pins)
    wheels = []
    for pin in pins:
        name, version = pin.split("==")
        prefix = f"{name.lower().replace('-', '_')}-{version}-"
        match = [w for w in sorted(os.listdir(dest)) if w.lower().startswith(prefix) and w.endswith(".whl")]
        if len(match) != 1:
            sys.exit(f"build_addon: expected one wheel {prefix}*.whl in {dest}, found {match}")
        wheels.append(os.path.join(dest, match[0]))
    return wheels


# --------------------------------------------------------------------------- packages

def blender_ext_script(explicit: str | None) -> str:
    """Blender's extension tool: ``explicit``, else the one in the installed bpy wheel."""
    if explicit:
        return explicit
    spec = importlib.util.find_spec("bpy")
    for base in (spec.submodule_search_locations or []) if spec else []:
        found = glob.glob(os.path.join(base, "*", "scripts", "addons_core", "bl_pkg", "cli", "blender_ext.py"))
        if found:
            return found[0]
    sys.exit("build_addon: bpy's blender_ext.py not found; install bpy (requirements.txt) or pass "
             "--blender-ext PATH")


def staged_manifest(text: str, wheels: list[str], platforms: list[str]) -> str:
    """The manifest for the build: ``platforms`` set to the ones built, and a top-level
    ``wheels = [...]`` inserted before its first table."""
    lines = text.splitlines(keepends=True)
    listed = [i for i, line in enumerate(lines) if line.startswith("platforms")]
    if len(listed) != 1:
        sys.exit("build_addon: blender_manifest.toml needs one single-line 'platforms = [...]'")
    lines[listed[0]] = "platforms = [" + ", ".join(f'"{p}"' for p in platforms) + "]\n"
    entry = "wheels = [\n" + "".join(f'  "./wheels/{os.path.basename(w)}",\n' for w in wheels) + "]\n\n"
    first_table = next((i for i, line in enumerate(lines) if line.startswith("[")), len(lines))
    return "".join(lines[:first_table]) + entry + "".join(lines[first_table:])


def build_extension(wheels: list[str], platforms: list[str], staging: str, dist: str,
                    tool: str) -> list[str]:
    """Stage the extension source, build one zip per platform and validate each."""
    src = os.path.join(staging, "extension")
    shutil.rmtree(src, ignore_errors=True)
    shutil.copytree(ADDON, src, ignore=shutil.ignore_patterns("__pycache__", "*.pyc", "vendor"))
    os.makedirs(os.path.join(src, "wheels"))
    for wheel in wheels:
        shutil.copy2(wheel, os.path.join(src, "wheels"))
    manifest = os.path.join(src, "blender_manifest.toml")
    with open(manifest, encoding="utf-8") as f:
        text = staged_manifest(f.read(), wheels, platforms)
    with open(manifest, "w", encoding="utf-8") as f:
        f.write(text)
    before = set(glob.glob(os.path.join(dist, "*.zip")))
    run([sys.executable, tool, "build", "--source-dir", src, "--output-dir", dist, "--split-platforms"])
    built = sorted(set(glob.glob(os.path.join(dist, "*.zip"))) - before)
    if not built:
        sys.exit("build_addon: blender_ext.py build wrote no zip")
    for path in built:
        run([sys.executable, tool, "validate", path])
    return built


def build_legacy(version: str, staging: str, dist: str) -> str:
    """``ercuts-<version>-legacy.zip``: folder ``ercuts/`` (add-on + ``vendor/ercuts_core``)."""
    src = os.path.join(staging, "legacy", PACKAGE)
    shutil.rmtree(os.path.dirname(src), ignore_errors=True)
    shutil.copytree(ADDON, src, ignore=shutil.ignore_patterns(
        "__pycache__", "*.pyc", "vendor", "blender_manifest.toml"))
    shutil.copytree(os.path.join(ROOT, "ercuts_core"), os.path.join(src, "vendor", "ercuts_core"),
                    ignore=IGNORE)
    out = os.path.join(dist, f"{PACKAGE}-{version}-legacy.zip")
    tmp = out + ".tmp"
    with zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as zf:
        for folder, dirs, files in os.walk(src):
            dirs.sort()
            for name in sorted(files):
                path = os.path.join(folder, name)
                zf.write(path, os.path.relpath(path, os.path.dirname(src)))
    os.replace(tmp, out)
    return out


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--platforms", nargs="+", choices=sorted(PLATFORM_TAGS), default=list(PLATFORM_TAGS))
    p.add_argument("--python", nargs="+", choices=PYTHONS, default=list(PYTHONS),
                   help="CPython versions to bundle wheels for (3.11: Blender 4.2-5.0; 3.13: 5.1+)")
    p.add_argument("--dist", default=os.path.join(ROOT, "dist"), help="output folder (default dist/)")
    p.add_argument("--build-dir", default=os.path.join(ROOT, "build"),
                   help="wheel cache and staging (default build/)")
    p.add_argument("--blender-ext", help="path of Blender's bl_pkg/cli/blender_ext.py")
    p.add_argument("--only", choices=("extension", "legacy"), help="build one kind of package")
    args = p.parse_args(argv)

    version = check_versions()
    staging = os.path.join(args.build_dir, "addon")
    os.makedirs(args.dist, exist_ok=True)
    for old in glob.glob(os.path.join(args.dist, f"{PACKAGE}-*.zip")):
        if args.only is None or (args.only == "legacy") == old.endswith("-legacy.zip"):
            os.remove(old)

    outputs = []
    if args.only != "legacy":
        tool = blender_ext_script(args.blender_ext)
        wheels = [build_core_wheel(os.path.join(staging, "core_wheel"), staging)]
        for platform in args.platforms:
            for python in args.python:
                wheels += download_wheels(platform, python, os.path.join(args.build_dir, "wheels"))
        outputs += build_extension(wheels, args.platforms, staging, args.dist, tool)
    if args.only != "extension":
        outputs.append(build_legacy(version, staging, args.dist))
    for path in outputs:
        log(f"{os.path.relpath(path, os.getcwd())}  {os.path.getsize(path) / 2**20:.1f} MiB")
    return 0


if __name__ == "__main__":
    sys.exit(main())
