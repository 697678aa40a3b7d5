"""A resumable checkpoint of a frame rendered as iterations: the merged film's sums, its sample
count and the list of iterations merged into it, in one ``.npz`` written atomically
(:mod:`ercuts_core.atomic`), so an interrupted driver loses at most the iterations that were
running (:mod:`ercuts_core.cluster`).

The film is stored field by field (every array, every dict of arrays — the AOV sums —, every
number and flag of :class:`~ercuts_core.film.Film`, and the window), so a film restored from a
checkpoint merges further iterations exactly as the film that was saved would. A checkpoint
carries a key (:func:`checkpoint_key`: the scene description's bytes and the settings that
change the image of an iteration), and a checkpoint of another scene or settings is refused,
never merged.
"""
from __future__ import annotations

import hashlib
import json
import os

import numpy as np

from .atomic import atomic_path
from .camera import Window
from .film import Film
from .settings import RenderSettings

#: Settings that do not change the image of iteration k: how many iterations and from where
#: (the checkpoint's iteration list says which are in it), the time budget, where it runs
#: and the ray-tracing threads.
KEY_EXCLUDED = ("iterations", "iteration_start", "time_limit", "cluster", "threads")
_ARRAY, _DICT, _SCALAR = "array.", "dict.", "scalar."


class CheckpointMismatch(ValueError):
    """The checkpoint belongs to another scene, other settings or another iteration range."""


def checkpoint_key(npz: bytes, settings: RenderSettings) -> str:
    """SHA-256 (hex) of the scene description's ``.npz`` bytes and the settings that change
    an iteration's image (all but :data:`KEY_EXCLUDED`)."""
    values = {k: v for k, v in settings.to_dict().items() if k not in KEY_EXCLUDED}
    h = hashlib.sha256(bytes(npz))
    h.update(json.dumps(values, sort_keys=True).encode())
    return h.hexdigest()


def save_checkpoint(path: str | os.PathLike, film: Film, iterations: list[int], key: str) -> None:
    """Write ``film`` (its sums and sample count), the merged ``iterations`` (in merge order) and
    ``key`` to ``path`` atomically."""
    data = {"key": np.array(key), "iterations": np.asarray(iterations, dtype=np.int64),
            "window": np.array(film.window.rect, dtype=np.int64)}
    for name, value in vars(film).items():
        if isinstance(value, np.ndarray):
            data[_ARRAY + name] = value
        elif isinstance(value, dict):
            data[_DICT + name] = np.array(sorted(value))
            for k, v in value.items():
                data[f"{_DICT}{name}.{k}"] = np.asarray(v)
        elif isinstance(value, (bool, int, float, np.number)):
            data[_SCALAR + name] = np.array(value)
    with atomic_path(path, ".npz") as tmp:
        np.savez(tmp, **data)


def load_checkpoint(path: str | os.PathLike, key: str) -> tuple[Film, list[int]] | None:
    """The film and iteration list saved at ``path``, or None when there is no file.

    Raises:
        CheckpointMismatch: the checkpoint's key is not ``key`` (another scene or settings).
    """
    if not os.path.exists(path):
        return None
    with np.load(path, allow_pickle=False) as z:
        if str(z["key"]) != key:
            raise CheckpointMismatch(
                f"checkpoint {os.fspath(path)} belongs to another scene or other settings; "
                "delete it or give another checkpoint path")
        film = Film(Window(*(int(v) for v in z["window"])))
        for entry in z.files:
            if entry.startswith(_ARRAY):
                setattr(film, entry[len(_ARRAY):], z[entry].copy())
            elif entry.startswith(_SCALAR):
                setattr(film, entry[len(_SCALAR):], z[entry].item())
            elif entry.startswith(_DICT) and entry.count(".") == 1:
                name = entry[len(_DICT):]
                setattr(film, name, {str(k): z[f"{entry}.{k}"].copy() for k in z[entry].reshape(-1)})
        return film, [int(k) for k in z["iterations"]]


def resumable(done: list[int], wanted: list[int], path: str | os.PathLike) -> int:
    """How many of ``wanted`` (iteration indices in merge order) the checkpoint's ``done``
    already holds: ``done`` must be their beginning (a merged film cannot lose an iteration).

    Raises:
        CheckpointMismatch: ``done`` is not a prefix of ``wanted``.
    """
    if list(done) != list(wanted[:len(done)]):
        raise CheckpointMismatch(
            f"checkpoint {os.fspath(path)} holds iterations {_span(done)}, not the beginning of "
            f"this render's {_span(wanted)}; delete it or render a range that starts with them")
    return len(done)


def _span(ks: list[int]) -> str:
    return f"{ks[0]}–{ks[-1]}" if len(ks) > 1 and ks == list(range(ks[0], ks[-1] + 1)) else str(list(ks))


__all__ = ["CheckpointMismatch", "checkpoint_key", "load_checkpoint", "resumable", "save_checkpoint"]
