"""Headless batch rendering with a real ``blender`` binary (Debian's 3.4.1 in CI), after the
README's install step for a render node (shared docs ``blender.md`` §5.3, §6):

1. ``scripts/build_addon.py --only legacy`` builds the legacy zip;
2. Blender installs and enables it and saves the preferences, into a temporary
   ``BLENDER_USER_SCRIPTS``/``BLENDER_USER_CONFIG`` (numpy, embreex, scipy and OpenEXR come
   from this environment's site-packages through ``PYTHONPATH``; the repository is *not* on
   the path, so the core is the copy vendored in the zip);
3. ``blender -b scene.blend -E ERCUTS -o //out/frame_#### -F OPEN_EXR -f 1`` (and ``-s/-e/-a``)
   renders a copy of a blend_scenes file; a ``--python-expr`` before ``-f`` makes it small
   (48 × 36 pixels, few samples: a few seconds per frame).

Skipped only when there is no ``blender`` binary (CI installs Debian's).
"""
from __future__ import annotations

import glob
import os
import shutil
import subprocess
import sys
import sysconfig

import numpy as np
import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
BLENDER = shutil.which("blender")
pytestmark = pytest.mark.skipif(BLENDER is None, reason="no blender binary (CI installs Debian's blender)")

W, H = 48, 36
#: Runs after the .blend is loaded and before -f/-a: a small, quick render, and the core's path.
SMALL = ("import bpy, ercuts_core; print('ERCUTS_CORE', ercuts_core.__file__); "
         "s = bpy.context.scene; s.render.resolution_x, s.render.resolution_y = %d, %d; "
         "s.render.resolution_percentage = 100; s.ercuts.samples = 4; s.ercuts.chain_length = 20; "
         "s.ercuts.iterations = 1; s.ercuts.time_limit = 60" % (W, H))


def run_blender(args, env, cwd, timeout=300) -> subprocess.CompletedProcess:
    return subprocess.run([BLENDER, *args], env=env, cwd=cwd, capture_output=True, text=True,
                          timeout=timeout)


@pytest.fixture(scope="module")
def node(tmp_path_factory):
    """A 'render node': the legacy zip installed and enabled in temporary user folders.

    Returns (env, workdir) with cornell_box.blend copied into workdir.
    """
    base = tmp_path_factory.mktemp("render_node")
    dist = base / "dist"
    subprocess.run([sys.executable, os.path.join(ROOT, "scripts", "build_addon.py"), "--only", "legacy",
                    "--dist", str(dist)], check=True, capture_output=True, timeout=300)
    (zip_path,) = glob.glob(str(dist / "ercuts-*-legacy.zip"))
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    env.update(BLENDER_USER_SCRIPTS=str(base / "scripts"), BLENDER_USER_CONFIG=str(base / "config"),
               PYTHONPATH=sysconfig.get_paths()["purelib"])
    install = ("import bpy; bpy.ops.preferences.addon_install(filepath=%r); "
               "bpy.ops.preferences.addon_enable(module='ercuts'); bpy.ops.wm.save_userpref()" % zip_path)
    proc = run_blender(["-b", "--python-exit-code", "1", "--python-expr", install], env, base)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert (base / "scripts" / "addons" / "ercuts" / "vendor" / "ercuts_core" / "__init__.py").is_file()
    work = base / "work"
    work.mkdir()
    shutil.copy2(os.path.join(ROOT, "blend_scenes", "cornell_box.blend"), work / "scene.blend")
    return env, work


def render(node, out, frames, extra_expr=""):
    """``blender -b scene.blend --python-expr … -E ERCUTS -o //<out>/frame_#### -F OPEN_EXR <frames>``."""
    env, work = node
    args = ["-b", str(work / "scene.blend"), "--python-expr", SMALL + extra_expr, "-E", "ERCUTS",
            "-o", f"//{out}/frame_####", "-F", "OPEN_EXR", *frames]
    return run_blender(args, env, work), work / out


def check_exr(path):
    """The EXR exists, is W × H, finite, and not black."""
    from ercuts_core.image_io import read_exr

    assert path.is_file(), path
    rgba = read_exr(path)["RGBA"]
    assert rgba.shape == (H, W, 4)
    assert np.isfinite(rgba).all()
    assert rgba[..., :3].mean() > 0.01


def test_single_frame(node):
    proc, out = render(node, "single", ["-f", "1"])
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    core = proc.stdout.split("ERCUTS_CORE ", 1)[1].split()[0]
    assert os.path.join("addons", "ercuts", "vendor", "ercuts_core") in core  # the zip's own core
    assert sorted(os.listdir(out)) == ["frame_0001.exr"]
    check_exr(out / "frame_0001.exr")


def test_frame_range_writes_every_frame(node):
    proc, out = render(node, "range", ["-s", "2", "-e", "4", "-a"], "; s.ercuts.integrator = 'PATH'")
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    assert sorted(os.listdir(out)) == ["frame_0002.exr", "frame_0003.exr", "frame_0004.exr"]
    for name in sorted(os.listdir(out)):
        check_exr(out / name)


def test_engine_listed(node):
    env, work = node
    proc = run_blender(["-b", "-E", "help"], env, work, timeout=120)
    assert "ERCUTS" in proc.stdout.split()


def test_no_camera_fails_without_output(node):
    """Blender itself refuses (3.4.1 prints 'Error: Cannot render, no camera' on stdout)."""
    drop = ("; [bpy.data.objects.remove(o) for o in list(bpy.data.objects) if o.type == 'CAMERA']"
            "; s.camera = None")
    proc, out = render(node, "no_camera", ["-f", "1"], drop)
    assert proc.returncode != 0
    assert "no camera" in (proc.stdout + proc.stderr).lower()
    assert not out.exists() or not os.listdir(out)


def test_engine_error_fails_with_message_on_stderr(node):
    """An error raised in the engine (a memory budget too small for the scene) is reported:
    exit status non-zero, the reason on stderr, no file written."""
    proc, out = render(node, "budget", ["-f", "1"], "; s.ercuts.memory_budget_mb = 1")
    assert proc.returncode != 0
    assert "memory budget of 1 MiB" in proc.stderr
    assert not out.exists() or not os.listdir(out)


def test_missing_dependencies_fail_with_a_clear_message(node):
    """Debian's Blender without PYTHONPATH has no numpy: the render must fail (non-zero exit,
    the missing module named, no file) instead of writing a black frame."""
    env, work = node
    bare = {k: v for k, v in env.items() if k != "PYTHONPATH"}
    check = run_blender(["-b", "--python-expr", "import importlib.util as u; "
                         "print('HAS_NUMPY', u.find_spec('numpy') is not None)"], bare, work, timeout=120)
    if "HAS_NUMPY True" in check.stdout:
        pytest.skip("this Blender's Python has numpy of its own")
    args = ["-b", str(work / "scene.blend"), "-E", "ERCUTS", "-o", "//missing/frame_####",
            "-F", "OPEN_EXR", "-f", "1"]
    proc = run_blender(args, bare, work)
    assert proc.returncode != 0
    assert "No module named 'numpy'" in proc.stderr
    assert not (work / "missing").exists() or not os.listdir(work / "missing")
