"""The G-buffer traced in chunks (progress and Esc between them) equals one traced at once."""
import numpy as np
import pytest

from ercuts_core.integrators.ercuts import vpl
from ercuts_core.scene import BuiltScene
from ercuts_core.scenes import cornell_box
from ercuts_core.validate import sanitize


def test_chunked_gbuffer_equals_one_batch_and_polls(monkeypatch):
    scene = BuiltScene(sanitize(cornell_box(16, 12, "mesh")).desc)
    whole, d_whole = vpl.build_gbuffer(scene, 2, np.random.default_rng(5))
    monkeypatch.setattr(vpl, "GBUFFER_CHUNK", 100)
    seen = []
    parts, d_parts = vpl.build_gbuffer(scene, 2, np.random.default_rng(5), poll=seen.append)
    # once the rays are generated, then after each of the 4 chunks of 384 rays / 100
    assert len(seen) == 5 and seen[0] == 0.0 and seen[-1] == 1.0 and seen == sorted(seen)
    np.testing.assert_array_equal(d_parts, d_whole)
    for field in ("valid", "p", "ng", "ns", "prim", "mat", "t"):
        np.testing.assert_array_equal(getattr(parts.surf, field), getattr(whole.surf, field))
    np.testing.assert_array_equal(parts.ns, whole.ns)


def test_a_raising_poll_stops_the_trace(monkeypatch):
    scene = BuiltScene(sanitize(cornell_box(8, 6, "mesh")).desc)
    monkeypatch.setattr(vpl, "GBUFFER_CHUNK", 10)

    def stop(f):
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        vpl.build_gbuffer(scene, 1, np.random.default_rng(0), poll=stop)
