"""A copy of the repository for tests that run its scripts and documented commands as a user
would, without writing into the checkout: the files git knows (tracked, and untracked ones
that are not ignored) as they are in the working tree, with ``.venv`` linked to the project's
environment (so ``scripts/setup_env.sh`` finds it up to date and installs nothing)."""
from __future__ import annotations

import os
import shutil
import subprocess
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
#: Never copied when git is unavailable and the tree is walked instead.
_SKIP_DIRS = {".git", ".venv", "out", "build", "dist", "__pycache__", ".pytest_cache", ".hypothesis"}


def venv_dir() -> str | None:
    """The project's environment: ``ROOT/.venv``, else the virtual environment running this."""
    for candidate in (os.path.join(ROOT, ".venv"), sys.prefix):
        if os.path.isfile(os.path.join(candidate, "bin", "python")) and (
                candidate != sys.prefix or sys.prefix != sys.base_prefix):
            return os.path.realpath(candidate)
    return None


def repo_files(root: str = ROOT) -> list[str]:
    """Paths (relative to ``root``) of the files git knows, or of every file outside
    :data:`_SKIP_DIRS` when ``root`` is not a git checkout."""
    try:
        out = subprocess.run(["git", "-C", root, "ls-files", "-z", "--cached", "--others",
                              "--exclude-standard"], capture_output=True, check=True).stdout
        return [p for p in out.decode().split("\0") if p]
    except (OSError, subprocess.CalledProcessError):
        found = []
        for folder, dirs, files in os.walk(root):
            dirs[:] = [d for d in dirs if d not in _SKIP_DIRS]
            found += [os.path.relpath(os.path.join(folder, f), root) for f in files]
        return found


def make_copy(dest: str, root: str = ROOT) -> str:
    """Copy the repository at ``root`` to ``dest`` (created) and link ``dest/.venv``."""
    os.makedirs(dest, exist_ok=True)
    for rel in repo_files(root):
        src = os.path.join(root, rel)
        if rel == ".venv" or not os.path.isfile(src):  # deleted in the working tree, or a link
            continue
        os.makedirs(os.path.dirname(os.path.join(dest, rel)), exist_ok=True)
        shutil.copy2(src, os.path.join(dest, rel))
    venv = venv_dir()
    if venv is None:
        raise RuntimeError("no project environment: run scripts/setup_env.sh first")
    os.symlink(venv, os.path.join(dest, ".venv"))
    return dest
