"""take_rows (ercuts_core/arrays.py) selects exactly the rows ``a[sel]`` does."""
from __future__ import annotations

import numpy as np
import pytest

from ercuts_core.arrays import take_rows


@pytest.mark.parametrize("shape", [(50,), (50, 3), (50, 4, 3)])
def test_take_rows_equals_fancy_indexing(shape):
    rng = np.random.default_rng(3)
    a = rng.random(shape)
    for sel in (rng.integers(-50, 50, 80), rng.random(50) < 0.4, np.zeros(0, np.int64),
                np.zeros(50, bool), slice(3, 40, 2), 7, -1):
        out = take_rows(a, sel)
        assert out.dtype == a.dtype and np.array_equal(out, a[sel])
    assert np.array_equal(take_rows(a.astype(np.int32), [1, 1, 0]), a.astype(np.int32)[[1, 1, 0]])


def test_take_rows_rejects_bad_indices_like_numpy():
    a = np.arange(10.0)
    with pytest.raises(IndexError):
        take_rows(a, np.ones(9, bool))   # np.compress would silently truncate
    with pytest.raises(IndexError):
        take_rows(a, [10])


def test_vecmath_dot_and_normalize():
    from ercuts_core.vecmath import dot, normalize

    rng = np.random.default_rng(3)
    a, b = rng.normal(size=(50, 3)), rng.normal(size=(50, 3))
    np.testing.assert_allclose(dot(a, b), (a * b).sum(axis=1), rtol=1e-14)
    v = np.vstack([a, np.zeros((1, 3))])
    unit, length = normalize(v)
    np.testing.assert_allclose(length[:-1], np.sqrt((a * a).sum(axis=1)), rtol=1e-14)
    np.testing.assert_allclose(np.linalg.norm(unit[:-1], axis=1), 1.0, rtol=1e-14)
    assert length[-1] == 0 and (unit[-1] == 0).all()          # a zero row stays zero
