"""Compiled kernels (numba) for the gather's hot loops, with the numpy code as the fallback.

numba is a pinned runtime dependency (``requirements.txt``; its wheels ship in the extension
zips).  When it cannot be imported (a Blender whose Python lacks it, a platform without an
llvmlite wheel) the renderer keeps working on the vectorized numpy code it always had, and
:func:`enabled` warns once, naming why.  ``ERCUTS_KERNELS=numpy`` forces the fallback
(benchmarks' A/B runs; tests use :func:`backend`).

Compiled functions are cached on disk (``cache=True``) in ``NUMBA_CACHE_DIR``, which this
module sets, unless the user set it, to a per-user cache folder (:func:`cache_dir`), so a
read-only installation (a system Blender, an extension folder) still caches.
"""
from __future__ import annotations

import os
import sys
import warnings
from contextlib import contextmanager

#: Environment variable that forces a backend ('numba' or 'numpy').
ENV = "ERCUTS_KERNELS"


def cache_dir() -> str:
    """Per-user folder of numba's on-disk cache of the compiled kernels."""
    if sys.platform == "win32":
        base = os.environ.get("LOCALAPPDATA") or os.path.expanduser("~")
    else:
        base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return os.path.join(base, "ercuts", "numba")


def _load():
    """(numba module or None, why not)."""
    os.environ.setdefault("NUMBA_CACHE_DIR", cache_dir())
    try:
        import numba
    except Exception as exc:          # ImportError, or OSError from llvmlite's shared library
        return None, f"{type(exc).__name__}: {exc}"
    return numba, ""


numba, WHY_NOT = _load()
#: numba could be imported.
NUMBA = numba is not None
_active = "numba" if NUMBA and os.environ.get(ENV, "numba") != "numpy" else "numpy"
_warned = False


def enabled() -> bool:
    """True when the compiled kernels are in use; the first False call without a forced
    numpy backend warns once (numba could not be loaded: the numpy fallback runs)."""
    global _warned
    if _active == "numba":
        return True
    if not NUMBA and not _warned and os.environ.get(ENV) != "numpy":
        _warned = True
        warnings.warn(f"Ercuts: numba is not available ({WHY_NOT}); the gather runs on its "
                      "slower numpy fallback", RuntimeWarning, stacklevel=2)
    return False


@contextmanager
def backend(name: str):
    """Use backend ``name`` ('numba' or 'numpy') inside the block (tests, benchmarks)."""
    global _active
    if name not in ("numba", "numpy"):
        raise ValueError(f"backend must be 'numba' or 'numpy', not {name!r}")
    if name == "numba" and not NUMBA:
        raise RuntimeError(f"numba is not available: {WHY_NOT}")
    old, _active = _active, name
    try:
        yield
    finally:
        _active = old


def jit(fn=None, *, inline: bool = False):
    """``numba.njit(cache=True, nogil=True)`` when numba loads, else ``fn`` unchanged;
    ``inline=True``: a helper inlined into its callers by numba (``inline='always'``)."""
    if fn is None:
        return lambda f: jit(f, inline=inline)
    if not NUMBA:
        return fn
    return numba.njit(cache=True, nogil=True, inline="always" if inline else "never")(fn)
