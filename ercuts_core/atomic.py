"""Atomic file output: write beside the destination under a temporary name, rename over it
only once complete, so a failed or cancelled write never leaves a truncated file nor
replaces a good one with a partial one.

Permissions are those a plain ``open(path, "w")`` gives: a new file gets
``0o666 & ~umask`` (the temporary file is created with mode 0o666 and the kernel applies
the umask and any default ACL; ``tempfile.mkstemp`` would make it private, 0o600), and a
file that is replaced keeps its permission bits, as it would when overwritten in place.
Standard library only: the add-on's statistics sidecar uses it too.
"""
from __future__ import annotations

import os
import secrets
import stat
from contextlib import contextmanager

#: Prefix of the temporary files (hidden; left behind only if the process is killed).
PREFIX = ".ercuts-"


def _create_temporary(directory: str, suffix: str) -> str:
    """A new empty file in ``directory``, created exclusively with mode 0o666 & ~umask."""
    for _ in range(100):
        tmp = os.path.join(directory, f"{PREFIX}{secrets.token_hex(6)}{suffix}")
        try:
            fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)
        except FileExistsError:
            continue
        os.close(fd)
        return tmp
    raise FileExistsError(f"no free temporary file name in {directory}")


@contextmanager
def atomic_path(path: str | os.PathLike, suffix: str = ""):
    """Yield a temporary path beside ``path`` for the caller to write; on success it is
    flushed to disk and renamed over ``path``; on any exception it is removed.

    Args:
        path: the destination (its directory is created).
        suffix: the temporary file's extension, for writers that choose the format by it
            (e.g. ``".exr"``; ``numpy.savez`` appends ``.npz`` to names without it).
    """
    path = os.fspath(path)
    directory = os.path.dirname(os.path.abspath(path))
    os.makedirs(directory, exist_ok=True)
    tmp = _create_temporary(directory, suffix)
    try:
        yield tmp
        try:
            os.chmod(tmp, stat.S_IMODE(os.stat(path).st_mode))  # replacing: keep its mode
        except FileNotFoundError:
            pass
        with open(tmp, "rb+") as fh:      # on disk before the rename makes it visible
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)


@contextmanager
def atomic_open(path: str | os.PathLike, mode: str = "w", **kwargs):
    """``open`` for writing (``"w"``/``"wb"``) through :func:`atomic_path`."""
    if mode not in ("w", "wb", "wt"):
        raise ValueError(f"atomic_open writes whole files; mode {mode!r} is not 'w' or 'wb'")
    with atomic_path(path, os.path.splitext(os.fspath(path))[1]) as tmp, open(tmp, mode, **kwargs) as fh:
        yield fh
