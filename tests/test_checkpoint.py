"""Checkpoints of a frame rendered as iterations (:mod:`ercuts_core.checkpoint`): the film comes
back exactly and merges further iterations as the saved one would; another scene's or other
settings' checkpoint is refused; only the beginning of a render's iterations resumes."""
from __future__ import annotations

import os

import numpy as np
import pytest

from ercuts_core import RenderSettings
from ercuts_core.checkpoint import (CheckpointMismatch, checkpoint_key, load_checkpoint, resumable,
                                    save_checkpoint)
from ercuts_core.cluster import npz_bytes
from ercuts_core.render import render_film
from ercuts_core.scenes import cornell_box

FAST = dict(integrator="ERCUTS", samples=2, chain_length=10, chains_per_pixel=0.5, direct_samples=4)


def test_film_round_trip_and_further_merges(tmp_path):
    desc, s = cornell_box(12, 9), RenderSettings(**FAST, seed=4)
    films = [render_film(desc, s.replace(iteration_start=k, iterations=1))[0] for k in range(3)]
    merged = films[0]
    merged.merge(films[1])
    key = checkpoint_key(npz_bytes(desc), s)
    path = tmp_path / "c.npz"
    save_checkpoint(path, merged, [0, 1], key)
    assert [p.name for p in tmp_path.iterdir()] == ["c.npz"]          # no temporary left
    film, done = load_checkpoint(path, key)
    assert done == [0, 1] and film.window == merged.window and film.passes_done == 2
    for name, value in vars(merged).items():
        if isinstance(value, np.ndarray):
            np.testing.assert_array_equal(getattr(film, name), value, err_msg=name)
    assert film.aov_sum.keys() == merged.aov_sum.keys() and film.classified == merged.classified
    film.merge(films[2])
    merged.merge(films[2])
    np.testing.assert_array_equal(film.image(), merged.image())
    for name in merged.aovs():
        np.testing.assert_array_equal(film.aovs()[name], merged.aovs()[name], err_msg=name)


def test_key_names_scene_and_image_settings_only(tmp_path):
    desc, s = cornell_box(12, 9), RenderSettings(**FAST)
    key = checkpoint_key(npz_bytes(desc), s)
    assert key == checkpoint_key(npz_bytes(desc), s.replace(iterations=9, time_limit=5.0, cluster="auto"))
    assert key != checkpoint_key(npz_bytes(desc), s.replace(seed=1))
    assert key != checkpoint_key(npz_bytes(cornell_box(12, 10)), s)
    film = render_film(desc, s)[0]
    save_checkpoint(tmp_path / "c.npz", film, [0], key)
    with pytest.raises(CheckpointMismatch, match="another scene or other settings"):
        load_checkpoint(tmp_path / "c.npz", checkpoint_key(npz_bytes(desc), s.replace(seed=1)))
    assert load_checkpoint(tmp_path / "missing.npz", key) is None


def test_only_the_beginning_of_the_iterations_resumes():
    assert resumable([3, 4], [3, 4, 5, 6], "c.npz") == 2
    assert resumable([], [0, 1], "c.npz") == 0
    message = "holds iterations 0–1, not the beginning of this render's 2–5"
    with pytest.raises(CheckpointMismatch, match=message):
        resumable([0, 1], [2, 3, 4, 5], "c.npz")
    with pytest.raises(CheckpointMismatch):
        resumable([0, 1, 2], [0, 1], os.path.join("x", "c.npz"))
