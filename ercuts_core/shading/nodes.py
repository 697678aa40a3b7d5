"""One function per shading-node type, vectorized over the N hits of one material.

Each node function has the signature ``node(inp: Inputs, params: dict, ctx) -> dict`` and
returns ``{output socket name: value}``. A value is ``(array, kind)``: kind 'f' for a float
(N,), 'c' for a colour (N, 3) and 'v' for a vector (N, 3). Implicit conversions follow
Blender's: colour → float is the luminance (Rec.709 weights), vector → float the average
of the components, float → colour/vector (f, f, f).

The formulas are Cycles' SVM kernels (``intern/cycles/kernel/svm/*.h``), re-derived in numpy;
each function names its source. ``ctx`` is a :class:`ercuts_core.shading.geometry.ShadingContext`
(positions, normals, UVs, tangents of the hits) plus the texture table.
"""
from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from .color import hsl_to_rgb, hsv_to_rgb, rgb_to_gray, rgb_to_hsl, rgb_to_hsv
from .textures import lookup, srgb_to_linear

F, C, V = "f", "c", "v"


# ---------------------------------------------------------------------------------------
# Values and inputs
# ---------------------------------------------------------------------------------------


def as_float(val) -> NDArray:
    """A value as (N,) float (colour → luminance, vector → average)."""
    arr, kind = val
    if kind == F:
        return arr
    return rgb_to_gray(arr) if kind == C else arr.mean(axis=1)


def as_vec(val) -> NDArray:
    """A value as (N, 3) (float → (f, f, f))."""
    arr, kind = val
    return np.repeat(arr[:, None], 3, axis=1) if kind == F else arr


class Inputs:
    """The input values of one node over N hits (linked or constant)."""

    def __init__(self, values: dict, n: int):
        self.values = values
        self.n = n

    def has(self, name: str) -> bool:
        return name in self.values

    def float(self, name: str, default: float = 0.0) -> NDArray:
        """(N,) float input ``name`` (Blender's default when absent)."""
        val = self.values.get(name)
        return np.full(self.n, float(default)) if val is None else as_float(val)

    def vec(self, name: str, default=(0.0, 0.0, 0.0)) -> NDArray:
        """(N, 3) colour or vector input ``name``."""
        val = self.values.get(name)
        return np.tile(np.asarray(default, np.float64)[:3], (self.n, 1)) if val is None else as_vec(val)

    def kind(self, name: str, default: str = F) -> str:
        val = self.values.get(name)
        return default if val is None else val[1]


def _safe_div(a: NDArray, b: NDArray) -> NDArray:
    """a/b where b ≠ 0, else 0 (Cycles ``safe_divide``)."""
    out = np.zeros(np.broadcast_shapes(np.shape(a), np.shape(b)))
    np.divide(a, b, out=out, where=np.broadcast_to(b != 0.0, out.shape))
    return out


def _lerp(a, b, t):
    return a + (b - a) * t


def _normalize(v: NDArray) -> NDArray:
    """Unit rows; zero rows stay zero (Cycles ``safe_normalize``)."""
    return _safe_div(v, np.linalg.norm(v, axis=1)[:, None])


# ---------------------------------------------------------------------------------------
# Input nodes
# ---------------------------------------------------------------------------------------


def value(inp, params, ctx):
    """VALUE: the constant ``params['value']``."""
    return {"Value": (np.full(ctx.n, float(params.get("value", 0.0))), F)}


def rgb(inp, params, ctx):
    """RGB: the constant colour ``params['value']`` (alpha ignored)."""
    c = np.asarray(params.get("value", (0.5, 0.5, 0.5)), np.float64).reshape(-1)[:3]
    return {"Color": (np.tile(c, (ctx.n, 1)), C)}


def tex_coord(inp, params, ctx):
    """TEX_COORD: UV (u, v, 0); Generated: position normalised to the object's *world* box;
    Object: world position; Normal: the shading normal (the description has no object
    transforms: Object and Normal are exact for objects with an identity transform,
    Generated for unrotated ones)."""
    return {"UV": (ctx.uv3, V), "Generated": (ctx.generated, V), "Object": (ctx.p, V),
            "Normal": (ctx.ns, V)}


def uvmap(inp, params, ctx):
    """UVMAP: the active render UV map (the description holds one map)."""
    return {"UV": (ctx.uv3, V)}


def light_path(inp, params, ctx):
    """LIGHT_PATH: every ray is treated as a camera ray (Is Camera Ray = 1, the rest 0)."""
    one, zero = np.ones(ctx.n), np.zeros(ctx.n)
    out = {name: (zero, F) for name in ("Is Shadow Ray", "Is Diffuse Ray", "Is Glossy Ray",
                                        "Is Singular Ray", "Is Reflection Ray", "Is Transmission Ray",
                                        "Is Volume Scatter Ray", "Ray Length", "Ray Depth",
                                        "Diffuse Depth", "Glossy Depth", "Transparent Depth",
                                        "Transmission Depth")}
    out["Is Camera Ray"] = (one, F)
    return out


# ---------------------------------------------------------------------------------------
# Textures and vectors
# ---------------------------------------------------------------------------------------


def tex_image(inp, params, ctx):
    """TEX_IMAGE: :func:`ercuts_core.shading.textures.lookup` at Vector.xy (default: UV),
    decoded after the interpolation for sRGB-encoded rows (``TextureTable.srgb``). An
    out-of-range texture row reads Cycles' magenta (the validator warns)."""
    uv = inp.vec("Vector")[:, :2] if inp.has("Vector") else ctx.uv
    tex = params.get("texture", -1)
    images, srgb = ctx.textures.images, ctx.textures.srgb
    # A family of materials (program.merge) gives one texture row per material
    idx = tex[ctx.lane_row] if isinstance(tex, np.ndarray) else np.full(ctx.n, int(tex))
    rgba = np.tile([1.0, 0.0, 1.0, 1.0], (ctx.n, 1))
    for row in np.unique(idx):
        if 0 <= row < len(images):
            sel = idx == row
            rgba[sel] = lookup(images[row], uv[sel], params.get("interpolation", "Linear"),
                               params.get("extension", "REPEAT"))
            if srgb[row]:
                rgba[sel, :3] = srgb_to_linear(rgba[sel, :3])
    return {"Color": (rgba[:, :3], C), "Alpha": (rgba[:, 3], F)}


def euler_matrix(rot: NDArray) -> NDArray:
    """(N, 3) XYZ Euler angles [rad] → (N, 3, 3) rotation R = Rz·Ry·Rx (Cycles
    ``euler_to_transform``, util/transform.h)."""
    cx, cy, cz = np.cos(rot).T
    sx, sy, sz = np.sin(rot).T
    return np.stack([np.stack([cy * cz, sy * sx * cz - cx * sz, sy * cx * cz + sx * sz], 1),
                     np.stack([cy * sz, sy * sx * sz + cx * cz, sy * cx * sz - sx * cz], 1),
                     np.stack([-sy, cy * sx, cy * cx], 1)], axis=1)


def mapping(inp, params, ctx):
    """MAPPING (Cycles ``svm_mapping``, kernel/svm/mapping_util.h), R = euler(Rotation):
    POINT R(v·s) + loc; TEXTURE Rᵀ(v − loc)/s; VECTOR R(v·s); NORMAL normalize(R(v/s))."""
    vec, loc = inp.vec("Vector"), inp.vec("Location")
    rot, scale = inp.vec("Rotation"), inp.vec("Scale", (1.0, 1.0, 1.0))
    R = euler_matrix(rot)
    kind = params.get("vector_type", "POINT")
    if kind == "TEXTURE":
        out = _safe_div(np.einsum("nji,nj->ni", R, vec - loc), scale)
    elif kind == "VECTOR":
        out = np.einsum("nij,nj->ni", R, vec * scale)
    elif kind == "NORMAL":
        out = _normalize(np.einsum("nij,nj->ni", R, _safe_div(vec, scale)))
    else:
        out = np.einsum("nij,nj->ni", R, vec * scale) + loc
    return {"Vector": (out, V)}


def sepxyz(inp, params, ctx):
    """SEPXYZ: the components of Vector."""
    v = inp.vec("Vector")
    return {"X": (v[:, 0], F), "Y": (v[:, 1], F), "Z": (v[:, 2], F)}


def combxyz(inp, params, ctx):
    """COMBXYZ: (X, Y, Z)."""
    return {"Vector": (np.stack([inp.float("X"), inp.float("Y"), inp.float("Z")], 1), V)}


def _vect_op(op: str, a, b, c, s):
    """Vector Math operations (Cycles ``svm_vector_math``, kernel/svm/math_util.h).
    Returns (vector (N, 3) or None, value (N,) or None)."""
    with np.errstate(invalid="ignore", over="ignore"):
        if op == "ADD":
            return a + b, None
        if op == "SUBTRACT":
            return a - b, None
        if op == "MULTIPLY":
            return a * b, None
        if op == "DIVIDE":
            return _safe_div(a, b), None
        if op == "MULTIPLY_ADD":
            return a * b + c, None
        if op == "CROSS_PRODUCT":
            return np.cross(a, b), None
        if op == "PROJECT":
            bb = (b * b).sum(1)
            return b * _safe_div((a * b).sum(1), bb)[:, None], None
        if op == "REFLECT":
            n = _normalize(b)
            return a - 2.0 * (n * a).sum(1)[:, None] * n, None
        if op == "DOT_PRODUCT":
            return None, (a * b).sum(1)
        if op == "DISTANCE":
            return None, np.linalg.norm(a - b, axis=1)
        if op == "LENGTH":
            return None, np.linalg.norm(a, axis=1)
        if op == "SCALE":
            return a * s[:, None], None
        if op == "NORMALIZE":
            return _normalize(a), None
        if op == "SNAP":
            return np.floor(_safe_div(a, b)) * b, None
        if op == "FLOOR":
            return np.floor(a), None
        if op == "CEIL":
            return np.ceil(a), None
        if op == "MODULO":
            return np.where(b != 0.0, np.fmod(a, np.where(b != 0.0, b, 1.0)), 0.0), None
        if op == "WRAP":
            return _wrap(a, b, c), None
        if op == "FRACTION":
            return a - np.floor(a), None
        if op == "ABSOLUTE":
            return np.abs(a), None
        if op == "MINIMUM":
            return np.minimum(a, b), None
        if op == "MAXIMUM":
            return np.maximum(a, b), None
        if op == "SINE":
            return np.sin(a), None
        if op == "COSINE":
            return np.cos(a), None
        if op == "TANGENT":
            return np.tan(a), None
    raise KeyError(op)


VECT_MATH_OPS = ("ADD", "SUBTRACT", "MULTIPLY", "DIVIDE", "MULTIPLY_ADD", "CROSS_PRODUCT", "PROJECT",
                 "REFLECT", "DOT_PRODUCT", "DISTANCE", "LENGTH", "SCALE", "NORMALIZE", "SNAP", "FLOOR",
                 "CEIL", "MODULO", "WRAP", "FRACTION", "ABSOLUTE", "MINIMUM", "MAXIMUM", "SINE",
                 "COSINE", "TANGENT")


def vect_math(inp, params, ctx):
    """VECT_MATH: Vector, Vector_001, Vector_002, Scale → Vector, Value (unused output 0)."""
    op = params.get("operation", "ADD")
    vec, val = _vect_op(op, inp.vec("Vector"), inp.vec("Vector_001"), inp.vec("Vector_002"),
                        inp.float("Scale", 1.0))
    vec = np.zeros((ctx.n, 3)) if vec is None else vec
    val = np.zeros(ctx.n) if val is None else val
    return {"Vector": (vec, V), "Value": (val, F)}


# ---------------------------------------------------------------------------------------
# Math
# ---------------------------------------------------------------------------------------


def _wrap(value, lo_or_max, hi_or_min):
    """Cycles ``wrapf(value, max, min)``: range = max − min;
    value − range·floor((value − min)/range)."""
    rng = lo_or_max - hi_or_min
    return np.where(rng != 0.0, value - rng * np.floor(_safe_div(value - hi_or_min, rng)), hi_or_min)


def _math_op(op: str, a: NDArray, b: NDArray, c: NDArray) -> NDArray:
    """Math node operations (Cycles ``svm_math``, kernel/svm/math_util.h, with its safe_*)."""
    if op == "ADD":
        return a + b
    if op == "SUBTRACT":
        return a - b
    if op == "MULTIPLY":
        return a * b
    if op == "DIVIDE":
        return _safe_div(a, b)
    if op == "MULTIPLY_ADD":
        return a * b + c
    if op == "POWER":         # safe_powf: negative base with a non-integer exponent → 0
        ok = ~((a < 0.0) & (b != np.trunc(b)))
        with np.errstate(divide="ignore", over="ignore", invalid="ignore"):
            out = np.power(np.where(ok, a, 1.0), b)
        return np.where(ok & np.isfinite(out), out, 0.0)
    if op == "LOGARITHM":     # safe_logf(a, b) = log(a)/log(b) for a, b > 0, else 0
        ok = (a > 0.0) & (b > 0.0)
        return _safe_div(np.log(np.where(ok, a, 1.0)), np.where(ok, np.log(np.where(ok, b, 1.0)), 0.0))
    if op == "SQRT":
        return np.sqrt(np.maximum(a, 0.0))
    if op == "INVERSE_SQRT":
        return np.where(a > 0.0, 1.0 / np.sqrt(np.where(a > 0.0, a, 1.0)), 0.0)
    if op == "ABSOLUTE":
        return np.abs(a)
    if op == "EXPONENT":
        with np.errstate(over="ignore"):
            return np.exp(a)
    if op == "MINIMUM":
        return np.minimum(a, b)
    if op == "MAXIMUM":
        return np.maximum(a, b)
    if op == "LESS_THAN":
        return (a < b).astype(np.float64)
    if op == "GREATER_THAN":
        return (a > b).astype(np.float64)
    if op == "SIGN":
        return np.sign(a)
    if op == "COMPARE":
        return (np.abs(a - b) <= np.maximum(c, np.finfo(np.float32).eps)).astype(np.float64)
    if op in ("SMOOTH_MIN", "SMOOTH_MAX"):   # smoothminf(a, b, k): polynomial smooth minimum
        s = -1.0 if op == "SMOOTH_MAX" else 1.0
        a, b = s * a, s * b
        h = np.maximum(c - np.abs(a - b), 0.0)
        smooth = np.minimum(a, b) - _safe_div(h * h * h, 6.0 * c * c)
        return s * np.where(c != 0.0, smooth, np.minimum(a, b))
    if op == "ROUND":
        return np.floor(a + 0.5)
    if op == "FLOOR":
        return np.floor(a)
    if op == "CEIL":
        return np.ceil(a)
    if op == "TRUNCATE":
        return np.trunc(a)
    if op == "FRACTION":
        return a - np.floor(a)
    if op == "MODULO":        # safe_modulo: fmod, 0 for b = 0
        return np.where(b != 0.0, np.fmod(a, np.where(b != 0.0, b, 1.0)), 0.0)
    if op == "FLOORED_MODULO":
        return np.where(b != 0.0, a - np.floor(_safe_div(a, b)) * b, 0.0)
    if op == "WRAP":
        return _wrap(a, b, c)
    if op == "SNAP":
        return np.floor(_safe_div(a, b)) * b
    if op == "PINGPONG":      # pingpongf(a, b) = |fract((a − b)/(2b))·2b − b|, 0 for b = 0
        x = _safe_div(a - b, 2.0 * b)
        return np.where(b != 0.0, np.abs((x - np.floor(x)) * 2.0 * b - b), 0.0)
    if op == "SINE":
        return np.sin(a)
    if op == "COSINE":
        return np.cos(a)
    if op == "TANGENT":
        return np.tan(a)
    if op == "ARCSINE":
        return np.arcsin(np.clip(a, -1.0, 1.0))
    if op == "ARCCOSINE":
        return np.arccos(np.clip(a, -1.0, 1.0))
    if op == "ARCTANGENT":
        return np.arctan(a)
    if op == "ARCTAN2":
        return np.arctan2(a, b)
    if op == "SINH":
        with np.errstate(over="ignore"):
            return np.sinh(a)
    if op == "COSH":
        with np.errstate(over="ignore"):
            return np.cosh(a)
    if op == "TANH":
        return np.tanh(a)
    if op == "RADIANS":
        return np.radians(a)
    if op == "DEGREES":
        return np.degrees(a)
    raise KeyError(op)


MATH_OPS = ("ADD", "SUBTRACT", "MULTIPLY", "DIVIDE", "MULTIPLY_ADD", "POWER", "LOGARITHM", "SQRT",
            "INVERSE_SQRT", "ABSOLUTE", "EXPONENT", "MINIMUM", "MAXIMUM", "LESS_THAN", "GREATER_THAN",
            "SIGN", "COMPARE", "SMOOTH_MIN", "SMOOTH_MAX", "ROUND", "FLOOR", "CEIL", "TRUNCATE",
            "FRACTION", "MODULO", "FLOORED_MODULO", "WRAP", "SNAP", "PINGPONG", "SINE", "COSINE",
            "TANGENT", "ARCSINE", "ARCCOSINE", "ARCTANGENT", "ARCTAN2", "SINH", "COSH", "TANH",
            "RADIANS", "DEGREES")


def math(inp, params, ctx):
    """MATH: Value, Value_001, Value_002 → Value; ``use_clamp`` clamps to [0, 1]."""
    out = _math_op(params.get("operation", "ADD"), inp.float("Value", 0.5), inp.float("Value_001", 0.5),
                   inp.float("Value_002", 0.5))
    if params.get("use_clamp", False):
        out = np.clip(out, 0.0, 1.0)
    return {"Value": (out, F)}


# ---------------------------------------------------------------------------------------
# Colour
# ---------------------------------------------------------------------------------------


def _blend(mode: str, t: NDArray, c1: NDArray, c2: NDArray) -> NDArray:
    """Mix RGB blend modes (Cycles ``svm_mix`` family, kernel/svm/color_util.h); t (N, 1)."""
    tm = 1.0 - t
    if mode == "MIX":
        return tm * c1 + t * c2
    if mode == "ADD":
        return c1 + t * c2
    if mode == "MULTIPLY":
        return c1 * (tm + t * c2)
    if mode == "SUBTRACT":
        return c1 - t * c2
    if mode == "SCREEN":
        return 1.0 - (tm + t * (1.0 - c2)) * (1.0 - c1)
    if mode == "DIVIDE":
        return np.where(c2 != 0.0, tm * c1 + t * _safe_div(c1, c2), c1)
    if mode == "DIFFERENCE":
        return _lerp(c1, np.abs(c1 - c2), t)
    if mode == "EXCLUSION":
        return np.maximum(_lerp(c1, c1 + c2 - 2.0 * c1 * c2, t), 0.0)
    if mode == "DARKEN":
        return _lerp(c1, np.minimum(c1, c2), t)
    if mode == "LIGHTEN":
        return _lerp(c1, np.maximum(c1, c2), t)
    if mode == "OVERLAY":
        return np.where(c1 < 0.5, c1 * (tm + 2.0 * t * c2), 1.0 - (tm + 2.0 * t * (1.0 - c2)) * (1.0 - c1))
    if mode == "SOFT_LIGHT":
        scr = 1.0 - (1.0 - c2) * (1.0 - c1)
        return tm * c1 + t * ((1.0 - c1) * c2 * c1 + c1 * scr)
    if mode == "LINEAR_LIGHT":
        return c1 + t * (2.0 * c2 - 1.0)
    raise KeyError(mode)


BLEND_MODES = ("MIX", "ADD", "MULTIPLY", "SUBTRACT", "SCREEN", "DIVIDE", "DIFFERENCE", "EXCLUSION",
               "DARKEN", "LIGHTEN", "OVERLAY", "SOFT_LIGHT", "LINEAR_LIGHT")


def mix(inp, params, ctx):
    """MIX (Blender ≥ 3.4): FLOAT and VECTOR lerp(A, B, Factor); RGBA the blend mode
    (``_blend``). ``clamp_factor`` (default on) clamps Factor to [0, 1], ``clamp_result``
    the RGBA result. A vector Factor (non-uniform VECTOR mix) blends per component."""
    data = params.get("data_type", "FLOAT")
    t = inp.vec("Factor", (0.5,) * 3) if (data == "VECTOR" and inp.kind("Factor") != F) \
        else inp.float("Factor", 0.5)[:, None]
    if params.get("clamp_factor", True):
        t = np.clip(t, 0.0, 1.0)
    if data == "FLOAT":
        return {"Result": (_lerp(inp.float("A"), inp.float("B"), t[:, 0]), F)}
    if data == "VECTOR":
        return {"Result": (_lerp(inp.vec("A"), inp.vec("B"), t), V)}
    out = _blend_colors(params, t, inp.vec("A", (0.5,) * 3), inp.vec("B", (0.5,) * 3), "clamp_result")
    return {"Result": (out, C)}


def _blend_colors(params, t, a, b, clamp_key: str):
    """(N, 3) ``params['blend_type']`` of colours a, b at factor t (unknown modes: MIX),
    clamped to [0, 1] when ``params[clamp_key]``; shared by MIX and MIX_RGB."""
    mode = params.get("blend_type", "MIX")
    out = _blend(mode if mode in BLEND_MODES else "MIX", t, a, b)
    return np.clip(out, 0.0, 1.0) if params.get(clamp_key, False) else out


def mix_rgb(inp, params, ctx):
    """MIX_RGB (Blender < 3.4, the exporter may keep it): Fac, Color1, Color2 → Color."""
    t = inp.float("Fac", 0.5)[:, None]
    if params.get("use_clamp_factor", True):
        t = np.clip(t, 0.0, 1.0)
    out = _blend_colors(params, t, inp.vec("Color1", (0.5,) * 3), inp.vec("Color2", (0.5,) * 3), "use_clamp")
    return {"Color": (out, C)}


def separate_color(inp, params, ctx):
    """SEPARATE_COLOR: RGB, or HSV / HSL (Cycles ``svm_node_separate_color``)."""
    c = inp.vec("Color", (0.8, 0.8, 0.8))
    mode = params.get("mode", "RGB")
    c = rgb_to_hsv(c) if mode == "HSV" else rgb_to_hsl(c) if mode == "HSL" else c
    return {"Red": (c[:, 0], F), "Green": (c[:, 1], F), "Blue": (c[:, 2], F)}


def combine_color(inp, params, ctx):
    """COMBINE_COLOR: RGB, or HSV / HSL → RGB."""
    c = np.stack([inp.float("Red"), inp.float("Green"), inp.float("Blue")], 1)
    mode = params.get("mode", "RGB")
    c = hsv_to_rgb(c) if mode == "HSV" else hsl_to_rgb(c) if mode == "HSL" else c
    return {"Color": (c, C)}


def invert(inp, params, ctx):
    """INVERT: lerp(c, 1 − c, Fac) (Cycles ``svm_node_invert``)."""
    c, t = inp.vec("Color"), inp.float("Fac", 1.0)[:, None]
    return {"Color": (_lerp(c, 1.0 - c, t), C)}


def gamma(inp, params, ctx):
    """GAMMA: c^γ for channels c > 0, others unchanged (Cycles ``svm_math_gamma_color``)."""
    c, g = inp.vec("Color", (1.0, 1.0, 1.0)), inp.float("Gamma", 1.0)[:, None]
    with np.errstate(over="ignore", divide="ignore"):
        out = np.where(c > 0.0, np.power(np.where(c > 0.0, c, 1.0), g), c)
    return {"Color": (np.where(np.isfinite(out), out, 0.0), C)}


def brightcontrast(inp, params, ctx):
    """BRIGHTCONTRAST: max((1 + contrast)·c + bright − contrast/2, 0) (Cycles
    ``svm_brightness_contrast``)."""
    c = inp.vec("Color", (1.0, 1.0, 1.0))
    bright, contrast = inp.float("Bright")[:, None], inp.float("Contrast")[:, None]
    return {"Color": (np.maximum((1.0 + contrast) * c + bright - 0.5 * contrast, 0.0), C)}


def hue_sat(inp, params, ctx):
    """HUE_SAT (Cycles ``svm_node_hsv``): h ← fract(h + Hue + 0.5), s ← clamp(s·Sat),
    v ← v·Value in HSV; lerp with the input by Fac; negative channels clamped to 0."""
    c = inp.vec("Color", (0.8, 0.8, 0.8))
    hsv = rgb_to_hsv(c)
    h = hsv[:, 0] + inp.float("Hue", 0.5) + 0.5
    hsv = np.stack([h - np.floor(h), np.clip(hsv[:, 1] * inp.float("Saturation", 1.0), 0.0, 1.0),
                    hsv[:, 2] * inp.float("Value", 1.0)], 1)
    out = _lerp(c, hsv_to_rgb(hsv), inp.float("Fac", 1.0)[:, None])
    return {"Color": (np.maximum(out, 0.0), C)}


def rgb_to_bw(inp, params, ctx):
    """RGB_TO_BW: luminance with Rec.709 weights."""
    return {"Val": (rgb_to_gray(inp.vec("Color", (0.5,) * 3)), F)}


def valtorgb(inp, params, ctx):
    """VALTORGB (Color Ramp, Blender's ``BKE_colorband_evaluate``): below the first stop its
    colour, above the last the last's; between stops LINEAR lerp, EASE lerp with the
    smoothstep 3t² − 2t³, CONSTANT the left stop. CARDINAL / B_SPLINE are evaluated as
    LINEAR (documented gap). Output Color (RGB) and Alpha."""
    fac = inp.float("Fac", 0.5)
    pos = np.asarray(params.get("positions", [0.0, 1.0]), np.float64).reshape(-1)
    cols = np.asarray(params.get("colors", [[0, 0, 0, 1], [1, 1, 1, 1]]), np.float64).reshape(len(pos), -1)
    if cols.shape[1] == 3:
        cols = np.concatenate([cols, np.ones((len(pos), 1))], 1)
    order = np.argsort(pos, kind="stable")
    pos, cols = pos[order], cols[order]
    mode = params.get("interpolation", "LINEAR")
    j = np.clip(np.searchsorted(pos, fac, side="right"), 1, max(len(pos) - 1, 1))   # right stop
    i = j - 1
    if len(pos) == 1:
        out = np.tile(cols[0], (ctx.n, 1))
    else:
        t = np.clip(_safe_div(fac - pos[i], pos[j] - pos[i]), 0.0, 1.0)
        if mode == "CONSTANT":
            t = (fac >= pos[j]).astype(np.float64)
        elif mode == "EASE":
            t = t * t * (3.0 - 2.0 * t)
        out = _lerp(cols[i], cols[j], t[:, None])
        out = np.where((fac <= pos[0])[:, None], cols[0], out)
        out = np.where((fac >= pos[-1])[:, None], cols[-1], out)
    return {"Color": (out[:, :3], C), "Alpha": (out[:, 3], F)}


def _lut(table: NDArray, x: NDArray) -> NDArray:
    """Piecewise-linear lookup of a curve sampled at k/(K − 1), k < K, on [0, 1]; linear
    extrapolation outside from the end segments (Cycles ``rgb_ramp_lookup`` with
    extrapolation, kernel/svm/ramp.h)."""
    K = len(table)
    f = x * (K - 1)
    i = np.clip(np.floor(f), 0, K - 2).astype(np.int64)
    t = f - i
    return table[i] + (table[i + 1] - table[i]) * t


def curve_rgb(inp, params, ctx):
    """CURVE_RGB: per channel R(C(x)) from a 256×4 LUT (columns C, R, G, B curves on
    [0, 1], Blender's ``curvemapping_evaluate_premulRGBF`` order), lerped with the input
    by Fac."""
    lut = np.asarray(params.get("lut", np.tile(np.linspace(0, 1, 256)[:, None], (1, 4))), np.float64)
    lut = lut.reshape(-1, 4) if lut.size >= 8 else np.tile(np.linspace(0, 1, 256)[:, None], (1, 4))
    c = inp.vec("Color", (1.0, 1.0, 1.0))
    out = np.stack([_lut(lut[:, 1 + k], _lut(lut[:, 0], c[:, k])) for k in range(3)], 1)
    return {"Color": (_lerp(c, out, inp.float("Fac", 1.0)[:, None]), C)}


# ---------------------------------------------------------------------------------------
# Normals
# ---------------------------------------------------------------------------------------


def normal_map(inp, params, ctx):
    """NORMAL_MAP (Cycles ``svm_node_normal_map``, kernel/svm/tex_coord.h), c = 2·Color − 1:

    * TANGENT: n' = normalize(c.x·T + c.y·sign·(N × T) + c.z·N) with the interpolated
      MikkTSpace tangent T, sign and the smooth normal N;
    * OBJECT: n' = normalize(M⁻ᵀ c) with ``object_matrix`` M (the object's 3×3
      world matrix; identity when absent);  WORLD: n' = normalize(c);
    * Strength s ≠ 1: n' ← normalize(N + (n' − N)·max(s, 0)).
    Normals are in the front-face orientation (the core's two-sided BSDF flips them).
    """
    c = 2.0 * inp.vec("Color", (0.5, 0.5, 1.0)) - 1.0
    space = params.get("space", "TANGENT")
    N = ctx.ns
    if space == "OBJECT":
        M = np.asarray(params.get("object_matrix", np.eye(3)), np.float64).reshape(3, 3)
        try:
            normal_from_object = np.linalg.inv(M).T
        except np.linalg.LinAlgError:
            normal_from_object = np.eye(3)
        n = _normalize(c @ normal_from_object.T)
    elif space == "WORLD":
        n = _normalize(c)
    else:
        T, sign = ctx.tangent, ctx.tangent_sign
        n = _normalize(c[:, :1] * T + c[:, 1:2] * sign[:, None] * np.cross(N, T) + c[:, 2:3] * N)
    strength = inp.float("Strength", 1.0)
    n = np.where((strength != 1.0)[:, None],
                 _normalize(N + (n - N) * np.maximum(strength, 0.0)[:, None]), n)
    return {"Normal": (np.where((np.linalg.norm(n, axis=1) > 0)[:, None], n, N), V)}


def bump(inp, params, ctx):
    """BUMP (Cycles ``svm_node_set_bump``, kernel/svm/displace.h): with the height h at the
    hit and h_x, h_y at p + dPdx, p + dPdy (``ctx.bump_heights``: the height subgraph
    re-evaluated at offset points of the triangle), Rx = dPdy × N, Ry = N × dPdx,
    det = dPdx·Rx, g = (h_x − h)·Rx + (h_y − h)·Ry,
    n' = normalize(|det|·N − Distance·sign(det)·g) (Distance negated if ``invert``),
    then n' ← normalize(s·n' + (1 − s)·N), s = max(Strength, 0)."""
    N = _normalize(inp.vec("Normal")) if inp.has("Normal") else ctx.ns
    h, hx, hy, dpdx, dpdy = ctx.bump_heights
    rx, ry = np.cross(dpdy, N), np.cross(N, dpdx)
    det = (dpdx * rx).sum(1)
    grad = (hx - h)[:, None] * rx + (hy - h)[:, None] * ry
    dist = inp.float("Distance", 1.0) * (-1.0 if params.get("invert", False) else 1.0)
    n = _normalize(np.abs(det)[:, None] * N - (dist * np.sign(det))[:, None] * grad)
    s = np.maximum(inp.float("Strength", 1.0), 0.0)[:, None]
    n = _normalize(s * n + (1.0 - s) * N)
    return {"Normal": (np.where((np.linalg.norm(n, axis=1) > 0)[:, None], n, N), V)}


#: Node type → (function, output sockets and their kinds).
NODES = {
    "VALUE": (value, {"Value": F}),
    "RGB": (rgb, {"Color": C}),
    "TEX_COORD": (tex_coord, {"UV": V, "Generated": V, "Object": V, "Normal": V}),
    "UVMAP": (uvmap, {"UV": V}),
    "LIGHT_PATH": (light_path, None),        # None: any socket name (all floats)
    "TEX_IMAGE": (tex_image, {"Color": C, "Alpha": F}),
    "MAPPING": (mapping, {"Vector": V}),
    "SEPXYZ": (sepxyz, {"X": F, "Y": F, "Z": F}),
    "COMBXYZ": (combxyz, {"Vector": V}),
    "VECT_MATH": (vect_math, {"Vector": V, "Value": F}),
    "MATH": (math, {"Value": F}),
    "MIX": (mix, {"Result": None}),
    "MIX_RGB": (mix_rgb, {"Color": C}),
    "SEPARATE_COLOR": (separate_color, {"Red": F, "Green": F, "Blue": F}),
    "COMBINE_COLOR": (combine_color, {"Color": C}),
    "INVERT": (invert, {"Color": C}),
    "GAMMA": (gamma, {"Color": C}),
    "BRIGHTCONTRAST": (brightcontrast, {"Color": C}),
    "HUE_SAT": (hue_sat, {"Color": C}),
    "RGB_TO_BW": (rgb_to_bw, {"Val": F}),
    "VALTORGB": (valtorgb, {"Color": C, "Alpha": F}),
    "CURVE_RGB": (curve_rgb, {"Color": C}),
    "NORMAL_MAP": (normal_map, {"Normal": V}),
    "BUMP": (bump, {"Normal": V}),
}
