"""Each shading node against its formula (Cycles' SVM kernels, re-derived here by hand)."""
from __future__ import annotations

import json

import numpy as np
import pytest

from ercuts_core.shading.geometry import MeshShading
from ercuts_core.shading.program import Ref, compile_program
from ercuts_core.shading.textures import TextureTable

# One right triangle in the z = 0 plane with UV = (x, y); tangent +x, sign +1
TRI = np.array([[[0.0, 0, 0], [1, 0, 0], [0, 1, 0]]])
UVS = np.array([[[0.0, 0], [1, 0], [0, 1]]])
TANGENTS = np.array([[[1.0, 0, 0, 1]] * 3])
N = np.array([0.0, 0.0, 1.0])


def context(b=None, textures=TextureTable(), tangents=TANGENTS, uvs=UVS):
    b = np.array([[1 / 3, 1 / 3, 1 / 3]]) if b is None else np.asarray(b, float)
    mesh = MeshShading(TRI, uvs, tangents, np.zeros(1, int), textures)
    n = np.tile(N, (len(b), 1))
    return mesh.context(np.zeros(len(b), int), b, n, n)


def run(nodes, socket, node=-1, ctx=None, n_textures=0):
    """Evaluate output ``socket`` of node ``node`` of a program made of ``nodes``."""
    prog, notes = compile_program(json.dumps({"version": 1, "nodes": nodes, "outputs": {}}), "T", n_textures)
    assert prog is not None and not notes, notes
    ctx = context() if ctx is None else ctx
    i = len(nodes) + node if node < 0 else node
    return prog._run(ctx, [Ref(i, socket)])[i][socket][0]


def one(type_, socket, inputs=None, params=None, **kw):
    return run([{"type": type_, "inputs": inputs or {}, "params": params or {}}], socket, **kw)[0]


def math(op, a, b=0.5, c=0.5, clamp=False):
    return one("MATH", "Value", {"Value": a, "Value_001": b, "Value_002": c},
               {"operation": op, "use_clamp": clamp})


@pytest.mark.parametrize("op, a, b, c, expected", [
    ("ADD", 1.5, 2.0, 0, 3.5), ("SUBTRACT", 1, 3, 0, -2), ("MULTIPLY", 2, -3, 0, -6),
    ("DIVIDE", 1, 4, 0, 0.25), ("DIVIDE", 1, 0, 0, 0.0), ("MULTIPLY_ADD", 2, 3, 4, 10),
    ("POWER", 2, 3, 0, 8), ("POWER", -2, 0.5, 0, 0.0), ("POWER", -2, 3, 0, -8),
    ("LOGARITHM", 8, 2, 0, 3), ("LOGARITHM", -1, 2, 0, 0), ("SQRT", 9, 0, 0, 3), ("SQRT", -1, 0, 0, 0),
    ("INVERSE_SQRT", 4, 0, 0, 0.5), ("ABSOLUTE", -2, 0, 0, 2), ("EXPONENT", 0, 0, 0, 1),
    ("MINIMUM", 1, 2, 0, 1), ("MAXIMUM", 1, 2, 0, 2), ("LESS_THAN", 1, 2, 0, 1), ("GREATER_THAN", 1, 2, 0, 0),
    ("SIGN", -3, 0, 0, -1), ("COMPARE", 1.0, 1.05, 0.1, 1), ("COMPARE", 1.0, 1.2, 0.1, 0),
    ("ROUND", 2.5, 0, 0, 3), ("FLOOR", -1.5, 0, 0, -2), ("CEIL", 1.2, 0, 0, 2), ("TRUNCATE", -1.7, 0, 0, -1),
    ("FRACTION", -0.25, 0, 0, 0.75), ("MODULO", -1, 3, 0, -1), ("MODULO", 1, 0, 0, 0),
    ("FLOORED_MODULO", -1, 3, 0, 2), ("WRAP", 5, 3, 1, 1), ("SNAP", 7, 3, 0, 6),
    ("PINGPONG", 3, 2, 0, 1), ("SINE", np.pi / 2, 0, 0, 1), ("ARCSINE", 2, 0, 0, np.pi / 2),
    ("ARCTAN2", 1, 1, 0, np.pi / 4), ("RADIANS", 180, 0, 0, np.pi), ("DEGREES", np.pi, 0, 0, 180),
    ("SMOOTH_MIN", 1.0, 1.2, 0.5, 1.0 - 0.3 ** 3 / (6 * 0.25)), ("SMOOTH_MAX", 1.0, 1.2, 0.5, 1.2 + 0.3 ** 3 / 1.5),
])
def test_math(op, a, b, c, expected):
    assert math(op, a, b, c) == pytest.approx(expected, abs=1e-12)


def test_math_clamp():
    assert math("ADD", 0.8, 0.5, clamp=True) == 1.0
    assert math("SUBTRACT", 0.2, 0.5, clamp=True) == 0.0


C1, C2, T = np.array([0.2, 0.6, 0.9]), np.array([0.5, 0.1, 0.0]), 0.4


def blend(mode, t=T, c1=C1, c2=C2, clamp=False):
    return one("MIX", "Result", {"Factor": t, "A": list(c1), "B": list(c2)},
               {"data_type": "RGBA", "blend_type": mode, "clamp_result": clamp})


def _overlay(a, b, t):
    return a * (1 - t + 2 * t * b) if a < 0.5 else 1 - (1 - t + 2 * t * (1 - b)) * (1 - a)


@pytest.mark.parametrize("mode, expected", [
    ("MIX", (1 - T) * C1 + T * C2),
    ("ADD", C1 + T * C2),
    ("MULTIPLY", C1 * (1 - T + T * C2)),
    ("SUBTRACT", C1 - T * C2),
    ("SCREEN", 1 - (1 - T + T * (1 - C2)) * (1 - C1)),
    ("DIVIDE", [(1 - T) * 0.2 + T * 0.2 / 0.5, (1 - T) * 0.6 + T * 0.6 / 0.1, 0.9]),  # ÷0 keeps A
    ("DIFFERENCE", (1 - T) * C1 + T * np.abs(C1 - C2)),
    ("DARKEN", (1 - T) * C1 + T * np.minimum(C1, C2)),
    ("LIGHTEN", (1 - T) * C1 + T * np.maximum(C1, C2)),
    ("OVERLAY", [_overlay(a, b, T) for a, b in zip(C1, C2)]),
    ("LINEAR_LIGHT", C1 + T * (2 * C2 - 1)),
])
def test_mix_rgba_blend_modes(mode, expected):
    np.testing.assert_allclose(blend(mode), expected, atol=1e-12)


def test_mix_factor_clamp_float_vector_and_unknown_mode():
    np.testing.assert_allclose(blend("MIX", t=1.5), C2)              # clamp_factor defaults on
    assert np.clip(blend("ADD", clamp=True), 0, 1).tolist() == blend("ADD", clamp=True).tolist()
    f = one("MIX", "Result", {"Factor": 0.25, "A": 2.0, "B": 6.0}, {"data_type": "FLOAT"})
    assert f == pytest.approx(3.0)
    v = one("MIX", "Result", {"Factor": [0, 0.5, 1], "A": [0, 0, 0], "B": [2, 2, 2]}, {"data_type": "VECTOR"})
    np.testing.assert_allclose(v, [0, 1, 2])
    prog, notes = compile_program(json.dumps({"version": 1, "nodes": [
        {"type": "MIX", "params": {"data_type": "RGBA", "blend_type": "HUE"}}], "outputs": {}}), "Mat", 0)
    assert prog is not None and "HUE" in notes[0] and "Mat" in notes[0] and "MIX" in notes[0]


def test_colour_nodes():
    np.testing.assert_allclose(one("INVERT", "Color", {"Fac": 0.25, "Color": [0.2, 0.4, 1.0]}),
                               0.75 * np.array([0.2, 0.4, 1.0]) + 0.25 * np.array([0.8, 0.6, 0.0]))
    np.testing.assert_allclose(one("GAMMA", "Color", {"Color": [0.25, -0.5, 1.0], "Gamma": 2.0}),
                               [0.0625, -0.5, 1.0])
    np.testing.assert_allclose(one("BRIGHTCONTRAST", "Color",
                                   {"Color": [0.5, 0.1, 0.9], "Bright": 0.1, "Contrast": 0.5}),
                               np.maximum(1.5 * np.array([0.5, 0.1, 0.9]) + 0.1 - 0.25, 0))
    assert one("RGB_TO_BW", "Val", {"Color": [1.0, 0.0, 0.0]}) == pytest.approx(0.2126)
    np.testing.assert_allclose(one("RGB", "Color", params={"value": [0.1, 0.2, 0.3, 1.0]}), [0.1, 0.2, 0.3])
    assert one("VALUE", "Value", params={"value": 4.5}) == 4.5


def test_separate_combine_hsv_hsl():
    for mode, rgb, expected in [("HSV", [1, 0, 0], [0, 1, 1]), ("HSV", [0, 1, 0], [1 / 3, 1, 1]),
                                ("HSV", [0.25, 0.5, 0.5], [0.5, 0.5, 0.5]), ("HSL", [1, 0, 0], [0, 1, 0.5]),
                                ("HSL", [0.25, 0.5, 0.5], [0.5, 1 / 3, 0.375]), ("RGB", [0.1, 0.2, 0.3], [0.1, 0.2, 0.3])]:
        nodes = [{"type": "SEPARATE_COLOR", "inputs": {"Color": rgb}, "params": {"mode": mode}}]
        got = [run(nodes, s)[0] for s in ("Red", "Green", "Blue")]
        np.testing.assert_allclose(got, expected, atol=1e-12, err_msg=mode)
        back = one("COMBINE_COLOR", "Color", {"Red": expected[0], "Green": expected[1], "Blue": expected[2]},
                   {"mode": mode})
        np.testing.assert_allclose(back, rgb, atol=1e-12, err_msg=mode)


def test_hue_saturation_value():
    c = [0.8, 0.3, 0.1]
    np.testing.assert_allclose(one("HUE_SAT", "Color", {"Color": c, "Hue": 0.5, "Saturation": 1.0,
                                                         "Value": 1.0, "Fac": 1.0}), c, atol=1e-12)
    # Hue + 1/3 turns red into green; Value scales; Saturation 0 gives grey v
    np.testing.assert_allclose(one("HUE_SAT", "Color", {"Color": [1, 0, 0], "Hue": 0.5 + 1 / 3}), [0, 1, 0], atol=1e-12)
    np.testing.assert_allclose(one("HUE_SAT", "Color", {"Color": c, "Value": 0.5}), np.array(c) * 0.5, atol=1e-12)
    np.testing.assert_allclose(one("HUE_SAT", "Color", {"Color": c, "Saturation": 0.0}), [0.8] * 3, atol=1e-12)


def test_color_ramp():
    params = {"positions": [0.2, 0.6], "colors": [[0, 0, 0, 1], [1, 0.5, 0, 0]]}
    for mode, fac, expected in [("LINEAR", 0.3, 0.25), ("LINEAR", 0.0, 0.0), ("LINEAR", 0.9, 1.0),
                                ("CONSTANT", 0.5, 0.0), ("CONSTANT", 0.7, 1.0), ("EASE", 0.3, 0.15625)]:
        col = one("VALTORGB", "Color", {"Fac": fac}, {**params, "interpolation": mode})
        assert col[0] == pytest.approx(expected) and col[1] == pytest.approx(expected / 2), (mode, fac)
    alpha = run([{"type": "VALTORGB", "inputs": {"Fac": 0.4}, "params": params}], "Alpha")[0]
    assert alpha == pytest.approx(0.5)


def test_rgb_curves():
    x = np.linspace(0, 1, 256)
    identity = np.stack([x] * 4, 1)
    c = [0.3, 0.55, 0.8]
    np.testing.assert_allclose(one("CURVE_RGB", "Color", {"Color": c}, {"lut": identity.tolist()}), c, atol=1e-12)
    lut = identity.copy()
    lut[:, 1] = 1 - x                               # R curve inverts; C curve halves
    lut[:, 0] = 0.5 * x
    got = one("CURVE_RGB", "Color", {"Color": c, "Fac": 1.0}, {"lut": lut.tolist()})
    np.testing.assert_allclose(got, [1 - 0.15, 0.275, 0.4], atol=1e-12)


def test_mapping_types_and_euler_order():
    v = [0.3, -0.2, 0.5]
    loc, rot, scale = [1, 2, 3], [0.3, -0.4, 1.1], [2, 0.5, 4]
    pt = one("MAPPING", "Vector", {"Vector": v, "Location": loc, "Rotation": rot, "Scale": scale},
             {"vector_type": "POINT"})
    back = one("MAPPING", "Vector", {"Vector": list(pt), "Location": loc, "Rotation": rot, "Scale": scale},
               {"vector_type": "TEXTURE"})
    np.testing.assert_allclose(back, v, atol=1e-12)       # TEXTURE is the inverse of POINT
    z90 = one("MAPPING", "Vector", {"Vector": [1, 0, 0], "Rotation": [0, 0, np.pi / 2]}, {"vector_type": "VECTOR"})
    np.testing.assert_allclose(z90, [0, 1, 0], atol=1e-12)
    # XYZ Euler: X first, then Z: (0, 1, 0) → X 90° → (0, 0, 1) → Z 90° → (0, 0, 1)
    xz = one("MAPPING", "Vector", {"Vector": [0, 1, 0], "Rotation": [np.pi / 2, 0, np.pi / 2]},
             {"vector_type": "VECTOR"})
    np.testing.assert_allclose(xz, [0, 0, 1], atol=1e-12)


def test_xyz_and_vector_math():
    nodes = [{"type": "COMBXYZ", "inputs": {"X": 1, "Y": 2, "Z": 3}},
             {"type": "VECT_MATH", "inputs": {"Vector": {"node": 0, "socket": "Vector"}, "Vector_001": [0, 0, 2]},
              "params": {"operation": "CROSS_PRODUCT"}},
             {"type": "SEPXYZ", "inputs": {"Vector": {"node": 1, "socket": "Vector"}}}]
    assert [run(nodes, s)[0] for s in "XYZ"] == [4.0, -2.0, 0.0]
    dot = run([{"type": "VECT_MATH", "inputs": {"Vector": [1, 2, 3], "Vector_001": [4, 5, 6]},
                "params": {"operation": "DOT_PRODUCT"}}], "Value")[0]
    assert dot == 32.0
    length = run([{"type": "VECT_MATH", "inputs": {"Vector": [3, 4, 0]}, "params": {"operation": "LENGTH"}}], "Value")
    assert length[0] == 5.0


def test_texture_coordinates_and_image():
    b = [[0.5, 0.25, 0.25], [0.2, 0.7, 0.1]]
    ctx = context(b)
    uv = run([{"type": "TEX_COORD"}], "UV", ctx=ctx)
    np.testing.assert_allclose(uv, [[0.25, 0.25, 0], [0.7, 0.1, 0]])
    gen = run([{"type": "TEX_COORD"}], "Generated", ctx=ctx)
    np.testing.assert_allclose(gen[:, :2], [[0.25, 0.25], [0.7, 0.1]])
    img = np.zeros((2, 2, 4), np.float32)
    img[0, 0], img[0, 1], img[1, 0], img[1, 1] = [1, 0, 0, 1], [0, 1, 0, 1], [0, 0, 1, 1], [1, 1, 1, 0.5]
    ctx = context(b, textures=TextureTable(("checker",), (img,)))
    col = run([{"type": "TEX_IMAGE", "params": {"texture": 0, "interpolation": "Closest"}}], "Color",
              ctx=ctx, n_textures=1)
    np.testing.assert_allclose(col, [[1, 0, 0], [0, 1, 0]])   # (0.25, 0.25) bottom-left; (0.7, 0.1) bottom-right
    no_uv = context(b, uvs=None)
    np.testing.assert_array_equal(run([{"type": "UVMAP"}], "UV", ctx=no_uv), 0.0)


def normal_map(color, strength=1.0, **ctx_kw):
    return run([{"type": "NORMAL_MAP", "inputs": {"Color": color, "Strength": strength}}], "Normal",
               ctx=context(**ctx_kw))[0]


def test_normal_map_tangent_frame():
    np.testing.assert_allclose(normal_map([0.5, 0.5, 1.0]), N, atol=1e-12)
    np.testing.assert_allclose(normal_map([1.0, 0.5, 0.5]), [1, 0, 0], atol=1e-12)        # c.x → T
    np.testing.assert_allclose(normal_map([0.5, 1.0, 0.5]), [0, 1, 0], atol=1e-12)        # c.y → N × T
    flipped = np.array([[[1.0, 0, 0, -1]] * 3])
    np.testing.assert_allclose(normal_map([0.5, 1.0, 0.5], tangents=flipped), [0, -1, 0], atol=1e-12)
    c = np.array([0.8, 0.3, 0.9])
    d = 2 * c - 1
    np.testing.assert_allclose(normal_map(list(c)), d / np.linalg.norm(d), atol=1e-12)
    half = normal_map(list(c), strength=0.5)
    full = d / np.linalg.norm(d)
    expected = N + (full - N) * 0.5
    np.testing.assert_allclose(half, expected / np.linalg.norm(expected), atol=1e-12)
    np.testing.assert_allclose(normal_map(list(c), strength=0.0), N, atol=1e-12)
    # Without tangents the frame comes from the UV gradient ∂p/∂u = +x here
    np.testing.assert_allclose(normal_map([1.0, 0.5, 0.5], tangents=None), [1, 0, 0], atol=1e-12)


def test_normal_map_world_and_object_space():
    nm = run([{"type": "NORMAL_MAP", "inputs": {"Color": [1.0, 0.5, 0.5]}, "params": {"space": "WORLD"}}], "Normal")
    np.testing.assert_allclose(nm[0], [1, 0, 0], atol=1e-12)
    scale = np.diag([2.0, 1.0, 1.0])
    nm = run([{"type": "NORMAL_MAP", "inputs": {"Color": [1.0, 1.0, 0.5]},
               "params": {"space": "OBJECT", "object_matrix": scale.tolist()}}], "Normal")
    expected = np.array([0.5, 1.0, 0.0])                  # M⁻ᵀ (1, 1, 0)
    np.testing.assert_allclose(nm[0], expected / np.linalg.norm(expected), atol=1e-12)


@pytest.mark.parametrize("distance, strength, invert", [(0.5, 1.0, False), (0.5, 1.0, True), (2.0, 0.5, False)])
def test_bump_of_a_linear_height_is_the_analytic_gradient(distance, strength, invert):
    # h = 0.3·x + 0.1·y on the plane z = 0 (N = +z): n ∝ N − d·∇h, blended by strength
    nodes = [{"type": "TEX_COORD"},
             {"type": "SEPXYZ", "inputs": {"Vector": {"node": 0, "socket": "Object"}}},
             {"type": "MATH", "inputs": {"Value": {"node": 1, "socket": "X"}, "Value_001": 0.3,
                                         "Value_002": 0.0}, "params": {"operation": "MULTIPLY"}},
             {"type": "MATH", "inputs": {"Value": {"node": 1, "socket": "Y"}, "Value_001": 0.1,
                                         "Value_002": {"node": 2, "socket": "Value"}},
              "params": {"operation": "MULTIPLY_ADD"}},
             {"type": "BUMP", "inputs": {"Height": {"node": 3, "socket": "Value"}, "Distance": distance,
                                         "Strength": strength}, "params": {"invert": invert}}]
    got = run(nodes, "Normal", ctx=context([[0.2, 0.3, 0.5], [0.6, 0.2, 0.2]]))
    d = -distance if invert else distance
    n = np.array([-d * 0.3, -d * 0.1, 1.0])
    n /= np.linalg.norm(n)
    n = strength * n + (1 - strength) * N
    np.testing.assert_allclose(got, np.tile(n / np.linalg.norm(n), (2, 1)), atol=1e-9)


def test_light_path_is_a_camera_ray():
    assert one("LIGHT_PATH", "Is Camera Ray") == 1.0
    assert one("LIGHT_PATH", "Is Shadow Ray") == 0.0


@pytest.mark.parametrize("text, fragment", [
    ("{not json", "unusable"),
    ('{"version": 2, "nodes": []}', "version"),
    ('{"version": 1, "nodes": [{"type": "TEX_NOISE"}]}', "node 0 (TEX_NOISE)"),
    ('{"version": 1, "nodes": [{"type": "MATH", "inputs": {"Value": {"node": 3, "socket": "Value"}}}]}', "node 0 (MATH)"),
    ('{"version": 1, "nodes": [{"type": "VALUE"}, {"type": "MATH", "inputs": {"Value": {"node": 0, "socket": "Nope"}}}]}',
     "node 1 (MATH)"),
    ('{"version": 1, "nodes": [{"type": "MATH", "inputs": {"Value": "x"}}]}', "node 0 (MATH)"),
    ('{"version": 1, "nodes": [], "outputs": {"base_color": [1, "a"]}}', "base_color"),
    ('[1, 2]', "unusable"),
])
def test_malformed_programs_give_one_message_and_no_program(text, fragment):
    prog, notes = compile_program(text, "Wood", 0)
    assert prog is None and len(notes) == 1
    assert "Material 'Wood'" in notes[0] and fragment in notes[0]


def test_recoverable_problems_keep_the_program():
    text = json.dumps({"version": 1, "nodes": [{"type": "MATH", "params": {"operation": "NOPE"}},
                                               {"type": "TEX_IMAGE", "params": {"texture": 5}}],
                       "outputs": {"base_color": {"node": 1, "socket": "Color"}, "bogus": 1.0}})
    prog, notes = compile_program(text, "Wood", 1)
    assert prog is not None and len(notes) == 3
    col = prog.evaluate(context(), ["base_color"])["base_color"]
    np.testing.assert_array_equal(col, [[1, 0, 1]])                      # magenta


def test_a_family_of_programs_evaluates_like_its_members():
    """Programs differing only in constants and texture rows merge into one (SceneShading
    evaluates a family at once); each lane gets its own material's constants."""
    from ercuts_core.shading.program import merge, signature
    imgs = (np.full((1, 1, 4), 0.25, np.float32), np.full((1, 1, 4), 0.75, np.float32))
    progs = []
    for k, (tex, gain) in enumerate([(0, 2.0), (1, 3.0), (1, 2.0)]):
        text = json.dumps({"version": 1, "nodes": [
            {"type": "TEX_IMAGE", "params": {"texture": tex}},
            {"type": "MATH", "inputs": {"Value": {"node": 0, "socket": "Alpha"}, "Value_001": gain},
             "params": {"operation": "MULTIPLY"}}],
            "outputs": {"roughness": {"node": 1, "socket": "Value"}, "base_color": {"node": 0, "socket": "Color"}}})
        progs.append(compile_program(text, f"M{k}", 2)[0])
    assert len({signature(p) for p in progs}) == 1
    family = merge(progs)
    ctx = context([[1 / 3] * 3] * 3, textures=TextureTable(("a", "b"), imgs))
    ctx.lane_row = np.array([0, 1, 2])
    got = family.evaluate(ctx, ["roughness", "base_color"])
    np.testing.assert_allclose(got["roughness"], [0.5, 2.25, 1.5])
    np.testing.assert_allclose(got["base_color"][:, 0], [0.25, 0.75, 0.75])
