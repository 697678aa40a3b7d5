"""Texture lookups against hand-computed values (Blender conventions: texel centres at (i + 0.5)/W,
row 0 at the bottom)."""
from __future__ import annotations

import numpy as np
import pytest

from ercuts_core.shading.textures import lookup

# A 2×3 image (H = 2, W = 3); texel value r = 10·row + column, g = row, b = column, a = 1
IMG = np.zeros((2, 3, 4), np.float32)
for i in range(2):
    for j in range(3):
        IMG[i, j] = (10 * i + j, i, j, 1)


def r(uv, interp="Linear", ext="REPEAT"):
    return lookup(IMG, np.asarray(uv, float).reshape(-1, 2), interp, ext)[:, 0]


def test_closest_reads_the_texel_containing_uv():
    # u = 0.5 → column floor(1.5) = 1; v = 0.75 → row floor(1.5) = 1 (rows from the bottom)
    assert r([0.5, 0.75], "Closest") == pytest.approx(11)
    assert r([0.01, 0.01], "Closest") == pytest.approx(0)
    assert r([0.99, 0.01], "Closest") == pytest.approx(2)


def test_linear_is_exact_at_texel_centres_and_bilinear_between():
    assert r([0.5 / 3, 0.25]) == pytest.approx(0)
    assert r([2.5 / 3, 0.75]) == pytest.approx(12)
    # Halfway between the centres of columns 0 and 1, rows 0 and 1: mean of 0, 1, 10, 11
    assert r([1.0 / 3, 0.5]) == pytest.approx(5.5)
    # A quarter of the way from column 1's centre to column 2's centre on row 0
    assert r([(1.5 + 0.25) / 3, 0.25]) == pytest.approx(1.25)


def test_repeat_wraps_and_extend_clamps():
    # u = 0 lies between column 2 (wrapped) and column 0 centres: mean 1 on row 0
    assert r([0.0, 0.25], ext="REPEAT") == pytest.approx(1.0)
    assert r([0.0, 0.25], ext="EXTEND") == pytest.approx(0.0)
    assert r([1.0 + 0.5 / 3, 0.25], ext="REPEAT") == pytest.approx(0.0)
    assert r([5.0, 0.25], ext="EXTEND") == pytest.approx(2.0)
    assert r([-3.2, 0.25], "Closest", "REPEAT") == r([0.8, 0.25], "Closest", "REPEAT")


def test_clip_is_transparent_black_outside_and_fades_at_the_border():
    out = lookup(IMG, np.array([[1.2, 0.5], [-0.1, 0.5], [0.5, 1.01]]), "Linear", "CLIP")
    np.testing.assert_array_equal(out, 0.0)
    # At u = 0 the left neighbour is outside: half of column 0 (value 0) and alpha 0.5
    a = lookup(IMG, np.array([[0.0, 0.25]]), "Linear", "CLIP")[0]
    assert a[3] == pytest.approx(0.5) and a[2] == pytest.approx(0.0)
    inside = lookup(IMG, np.array([[0.5, 0.5]]), "Closest", "CLIP")[0]
    assert inside[3] == 1


def test_mirror_reflects_at_the_edges():
    # Column index −1 mirrors to 0, index 3 to 2, index 4 to 1
    assert r([-0.5 / 3, 0.25], "Closest", "MIRROR") == pytest.approx(0)
    assert r([3.5 / 3, 0.25], "Closest", "MIRROR") == pytest.approx(2)
    assert r([4.5 / 3, 0.25], "Closest", "MIRROR") == pytest.approx(1)
    assert r([6.5 / 3, 0.25], "Closest", "MIRROR") == pytest.approx(0)   # period 2W
    assert r([0.0, 0.25], "Linear", "MIRROR") == pytest.approx(0.0)      # 0 and its mirror


def test_cubic_falls_back_to_linear_and_nonfinite_uv_is_safe():
    uv = np.random.default_rng(0).random((50, 2)) * 3 - 1
    np.testing.assert_array_equal(lookup(IMG, uv, "Cubic"), lookup(IMG, uv, "Linear"))
    out = lookup(IMG, np.array([[np.nan, 0.5], [np.inf, -np.inf], [1e30, 2.0]]), "Linear")
    assert np.isfinite(out).all()


def test_vectorized_shapes():
    out = lookup(IMG, np.zeros((0, 2)))
    assert out.shape == (0, 4)
    assert lookup(IMG, np.zeros((7, 2))).shape == (7, 4)


def test_srgb_encoded_rows_interpolate_encoded_then_decode():
    """Cycles' compress_as_srgb: a white and a blue texel (8-bit sRGB), Linear lookup at the
    midpoint reads EOTF((a + b)/2), not (EOTF(a) + EOTF(b))/2; Closest reads EOTF(texel)."""
    import json

    from ercuts_core.shading.geometry import MeshShading
    from ercuts_core.shading.program import compile_program
    from ercuts_core.shading.textures import TextureTable, srgb_to_linear

    enc = np.array([[[0.85, 0.8, 0.7, 1.0], [0.25, 0.35, 0.6, 1.0]]], np.float32)    # (1, 2, 4)
    eotf = lambda c: np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)  # noqa: E731
    table = TextureTable(("t",), (enc,), (True,))
    assert table.srgb == (True,) and TextureTable(("t",), (enc,)).srgb == (False,)
    np.testing.assert_allclose(table.linear(0)[..., :3], eotf(enc[..., :3].astype(np.float64)), rtol=1e-6)
    np.testing.assert_allclose(srgb_to_linear(np.array([-0.1, 0.0, 0.04, 1.0])), [0, 0, 0.04 / 12.92, 1])
    tri = np.array([[[0, 0, 0], [1, 0, 0], [0, 1, 0]]], float)
    mesh = MeshShading(tri, np.array([[[0, 0], [1, 0], [0, 1]]], np.float32), None, np.zeros(1, int), table)
    b = np.array([[0.5, 0.5, 0.0], [0.75, 0.2, 0.05]])          # u = 0.5: midway between centres
    ctx = mesh.context(np.zeros(2, int), b, np.tile([0, 0, 1.0], (2, 1)), np.tile([0, 0, 1.0], (2, 1)))
    got = {}
    for interp, want in (("Linear", eotf((enc[0, 0, :3] + enc[0, 1, :3]) / 2.0)),
                         ("Closest", eotf(enc[0, 1, :3].astype(np.float64)))):
        node = {"type": "TEX_IMAGE", "params": {"texture": 0, "interpolation": interp, "extension": "EXTEND"}}
        prog = {"version": 1, "nodes": [node],
                "outputs": {"base_color": {"node": 0, "socket": "Color"}}}
        got[interp] = compile_program(json.dumps(prog), "M", 1)[0].evaluate(ctx, ["base_color"])["base_color"]
        np.testing.assert_allclose(got[interp][0], want, rtol=1e-6, err_msg=interp)
    linear_mid = (eotf(enc[0, 0, :3]) + eotf(enc[0, 1, :3])) / 2.0
    assert got["Linear"][0, 0] < 0.75 * linear_mid[0]           # red: 29 % darker than linear-space
