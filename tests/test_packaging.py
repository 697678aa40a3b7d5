"""The packages users install, built by ``scripts/build_addon.py`` (shared docs ``blender.md`` §4):
the extension zip (Blender ≥ 4.2) builds, passes Blender's own validator and holds the manifest,
the add-on, the core wheel and the embreex/scipy/OpenEXR/numba/llvmlite wheels (no numpy); the legacy zip
(Blender 3.x) is one ``ercuts/`` folder with the core vendored, importable without the
repository; the add-on uses relative imports only. The extension is also installed with bpy
5.0.1's extension operator and renders from its own wheels.

The build downloads the wheels from PyPI once (cached in ``build/wheels/``); it is limited
here to linux-x64 and CPython 3.11.
"""
from __future__ import annotations

import ast
import glob
import importlib.util
import os
import subprocess
import sys
import tomllib
import zipfile

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SCRIPT = os.path.join(ROOT, "scripts", "build_addon.py")


def _load_build_addon():
    spec = importlib.util.spec_from_file_location("build_addon", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


build_addon = _load_build_addon()
VERSION = build_addon.versions()["pyproject.toml"]


@pytest.fixture(scope="module")
def dist(tmp_path_factory):
    """dist/ with ercuts-<v>-linux_x64.zip and ercuts-<v>-legacy.zip."""
    out = tmp_path_factory.mktemp("dist")
    proc = subprocess.run([sys.executable, SCRIPT, "--platforms", "linux-x64", "--python", "3.11",
                           "--dist", str(out)], capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert sorted(os.listdir(out)) == [f"ercuts-{VERSION}-legacy.zip", f"ercuts-{VERSION}-linux_x64.zip"]
    return out


def _manifest(zf: zipfile.ZipFile) -> dict:
    return tomllib.loads(zf.read("blender_manifest.toml").decode())


def test_versions_agree():
    found = build_addon.versions()
    assert set(found) == {"pyproject.toml", "blender_manifest.toml", "bl_info"}
    assert len(set(found.values())) == 1, found


def test_staged_manifest_lists_wheels_at_top_level():
    text = 'id = "ercuts"\nplatforms = ["linux-x64", "windows-x64"]\n\n[build]\npaths = ["a"]\n'
    staged = tomllib.loads(build_addon.staged_manifest(text, ["/x/wheels/a-1-py3-none-any.whl"],
                                                       ["linux-x64"]))
    assert staged["wheels"] == ["./wheels/a-1-py3-none-any.whl"]  # not inside [build]
    assert staged["platforms"] == ["linux-x64"]
    assert staged["build"] == {"paths": ["a"]}


def test_extension_zip_contents(dist):
    with zipfile.ZipFile(dist / f"ercuts-{VERSION}-linux_x64.zip") as zf:
        names = zf.namelist()
        m = _manifest(zf)
        core_names = zipfile.ZipFile(zf.open(next(n for n in names if "ercuts_core-" in n))).namelist()
        init = zf.read("__init__.py").decode()
    assert (m["id"], m["type"], m["version"], m["blender_version_min"]) == ("ercuts", "add-on", VERSION, "4.2.0")
    assert m["tags"] == ["Render"] and all(x.startswith("SPDX:") for x in m["license"])
    assert m["platforms"] == ["linux-x64"]
    assert set(m["permissions"]) == {"files"}  # the statistics sidecar writes next to frames
    wheels = [w.removeprefix("./") for w in m["wheels"]]
    assert set(wheels) == {n for n in names if n.endswith(".whl")}  # listed == shipped
    for prefix in ("ercuts_core-", "embreex-", "scipy-", "openexr-", "numba-", "llvmlite-"):
        (wheel,) = [w for w in wheels if w.startswith("wheels/" + prefix)]
        assert prefix == "ercuts_core-" or "-cp311-cp311-" in wheel, wheel
        assert prefix == "ercuts_core-" or "linux" in wheel, wheel
    assert not [w for w in wheels if "numpy" in w]  # Blender ships numpy
    assert not [w for w in wheels if w.startswith("wheels/ray-")]  # Ray: the optional 'cluster' extra
    assert "bl_info" in init and "preferences" in init
    assert not [n for n in names if "__pycache__" in n or n.endswith(".pyc") or n.startswith("vendor/")]
    core_py = {os.path.relpath(p, ROOT).replace(os.sep, "/")
               for p in glob.glob(os.path.join(ROOT, "ercuts_core", "**", "*.py"), recursive=True)}
    assert core_py <= set(core_names)


def test_extension_zip_validates_and_validator_rejects_a_bad_manifest(dist, tmp_path):
    tool = build_addon.blender_ext_script(None)
    good = dist / f"ercuts-{VERSION}-linux_x64.zip"
    proc = subprocess.run([sys.executable, tool, "validate", str(good)], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    bad = tmp_path / "bad.zip"
    with zipfile.ZipFile(good) as src, zipfile.ZipFile(bad, "w") as dst:
        for info in src.infolist():
            data = src.read(info)
            if info.filename == "blender_manifest.toml":
                data = data.replace(b'id = "ercuts"', b'id = "not valid!"')
            dst.writestr(info, data)
    proc = subprocess.run([sys.executable, tool, "validate", str(bad)], capture_output=True, text=True)
    assert proc.returncode != 0


def test_legacy_zip_layout(dist):
    with zipfile.ZipFile(dist / f"ercuts-{VERSION}-legacy.zip") as zf:
        names = zf.namelist()
    assert {n.split("/")[0] for n in names} == {"ercuts"}
    assert "ercuts/__init__.py" in names and "ercuts/preferences.py" in names
    assert "ercuts/vendor/ercuts_core/__init__.py" in names
    assert "ercuts/vendor/ercuts_core/integrators/bdpt.py" in names
    assert not [n for n in names if n.endswith((".whl", ".pyc", "blender_manifest.toml"))]


def test_legacy_zip_registers_with_its_vendored_core(dist, tmp_path):
    """Unzipped into an add-ons folder, the package registers under its own name and imports
    the core it carries, with the repository off ``sys.path`` (bpy 5.0.1 in a subprocess)."""
    with zipfile.ZipFile(dist / f"ercuts-{VERSION}-legacy.zip") as zf:
        zf.extractall(tmp_path)
    code = (
        "import os, sys\n"
        f"sys.path = [p for p in sys.path if p not in ('', {ROOT!r})]\n"
        "import bpy\n"
        f"sys.path.insert(0, {str(tmp_path)!r})\n"
        "import ercuts\n"
        "ercuts.register(); ercuts.unregister(); ercuts.register()\n"
        "import ercuts_core\n"
        "from ercuts import dependencies\n"
        "print('CORE', ercuts_core.__file__)\n"
        "print('MISSING', dependencies.missing(dependencies.status()))\n"
        "bpy.context.scene.render.engine = 'ERCUTS'\n"
    )
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300,
                          cwd=tmp_path)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert f"CORE {tmp_path / 'ercuts' / 'vendor' / 'ercuts_core' / '__init__.py'}" in proc.stdout
    assert "MISSING []" in proc.stdout


#: Top-level modules the add-on may import absolutely (everything inside it is relative).
EXTERNAL = {"bpy", "bpy_extras", "mathutils", "addon_utils", "gpu", "gpu_extras", "_cycles", "numpy",
            "ercuts_core", "embreex", "scipy", "OpenEXR"}


def test_addon_imports_are_relative():
    """Legacy add-on → extension rule (shared docs blender.md §4.2): the package is installed as
    ``ercuts`` or ``bl_ext.<repo>.ercuts``, so nothing inside may import it by name."""
    offenders = []
    for path in glob.glob(os.path.join(ROOT, "addon", "**", "*.py"), recursive=True):
        with open(path, encoding="utf-8") as f:
            tree = ast.parse(f.read(), path)
        for node in ast.walk(tree):
            if isinstance(node, ast.Import):
                tops = [alias.name.split(".")[0] for alias in node.names]
            elif isinstance(node, ast.ImportFrom) and node.level == 0:
                tops = [node.module.split(".")[0]]
            else:
                continue
            for top in tops:
                if top not in EXTERNAL and top not in sys.stdlib_module_names:
                    offenders.append(f"{os.path.relpath(path, ROOT)}:{node.lineno} imports {top}")
    assert not offenders, offenders


def test_extension_installs_and_renders_in_bpy(dist, tmp_path):
    """bpy 5.0.1's own extension installer (``extensions.package_install_files``) installs the zip
    into a temporary user folder and enables it; with the extension's site-packages first on
    ``sys.path`` the core, embreex, scipy, OpenEXR and numba come from its wheels (the compiled
    kernels load), and a small ERCUTS render of the Cornell box through the installed engine
    (the gather's numba kernels next to embreex) writes a finite, non-black EXR."""
    if importlib.util.find_spec("bpy") is None:
        pytest.skip("bpy module not installed")
    out = tmp_path / "out.exr"
    code = f"""
import os, sys
import bpy
r = bpy.ops.extensions.package_install_files(filepath={str(dist / f'ercuts-{VERSION}-linux_x64.zip')!r},
                                             repo="user_default", enable_on_install=True)
assert r == {{"FINISHED"}}, r
assert "bl_ext.user_default.ercuts" in bpy.context.preferences.addons
local = os.path.join(bpy.utils.user_resource("EXTENSIONS"), ".local")
site = [p for p in sys.path if p.startswith(local)]
assert len(site) == 1, sys.path
sys.path.insert(0, site[0])
names = ("embreex", "scipy", "OpenEXR", "numba", "llvmlite", "ercuts_core")
for loaded in [m for m in sys.modules if m.split(".")[0] in names]:
    sys.modules.pop(loaded)       # all first: numba must not keep another llvmlite
for name in names:
    module = __import__(name)
    assert module.__file__.startswith(site[0]), module.__file__
from ercuts_core import kernels
assert kernels.NUMBA and kernels.enabled(), kernels.WHY_NOT
prefs = bpy.context.preferences.addons["bl_ext.user_default.ercuts"].preferences
assert prefs.default_threads == 0
bpy.ops.wm.open_mainfile(filepath={os.path.join(ROOT, "blend_scenes", "cornell_box.blend")!r})
s = bpy.context.scene
s.render.resolution_x, s.render.resolution_y, s.render.resolution_percentage = 40, 30, 100
s.ercuts.integrator, s.ercuts.samples, s.ercuts.time_limit = "ERCUTS", 4, 20
s.render.filepath = {str(out)!r}
s.render.image_settings.file_format = "OPEN_EXR"
assert bpy.ops.render.render(write_still=True) == {{"FINISHED"}}
"""
    env = dict(os.environ, BLENDER_USER_RESOURCES=str(tmp_path / "user"))
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=600,
                          cwd=tmp_path, env=env)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    import numpy as np

    from ercuts_core.image_io import read_exr

    rgba = read_exr(out)["RGBA"]
    assert rgba.shape == (30, 40, 4) and np.isfinite(rgba).all() and rgba[..., :3].mean() > 0.01


def test_build_needs_matching_versions(monkeypatch):
    """check_versions() refuses to build when bl_info, the manifest and pyproject disagree."""
    monkeypatch.setattr(build_addon, "versions",
                        lambda: {"pyproject.toml": "0.1.0", "blender_manifest.toml": "0.2.0", "bl_info": "0.1.0"})
    with pytest.raises(SystemExit, match="versions disagree"):
        build_addon.check_versions()
