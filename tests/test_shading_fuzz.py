"""Random programs over random hits: never an exception, a warning or a non-finite output
(the warnings policy in pyproject.toml turns any numpy warning into a failure)."""
from __future__ import annotations

import json

import numpy as np
import pytest

from ercuts_core.shading.geometry import MeshShading
from ercuts_core.shading.nodes import BLEND_MODES, MATH_OPS, NODES, VECT_MATH_OPS
from ercuts_core.shading.program import OUTPUTS, compile_program
from ercuts_core.shading.textures import EXTENSIONS, TextureTable

PARAMS = {
    "MATH": lambda r: {"operation": r.choice(MATH_OPS), "use_clamp": bool(r.integers(2))},
    "VECT_MATH": lambda r: {"operation": r.choice(VECT_MATH_OPS)},
    "MIX": lambda r: {"data_type": r.choice(["FLOAT", "RGBA", "VECTOR"]), "blend_type": r.choice(BLEND_MODES),
                      "clamp_factor": bool(r.integers(2)), "clamp_result": bool(r.integers(2))},
    "MIX_RGB": lambda r: {"blend_type": r.choice(BLEND_MODES)},
    "TEX_IMAGE": lambda r: {"texture": int(r.integers(-1, 3)), "extension": r.choice(EXTENSIONS),
                            "interpolation": r.choice(["Closest", "Linear", "Cubic"])},
    "MAPPING": lambda r: {"vector_type": r.choice(["POINT", "TEXTURE", "VECTOR", "NORMAL"])},
    "SEPARATE_COLOR": lambda r: {"mode": r.choice(["RGB", "HSV", "HSL"])},
    "COMBINE_COLOR": lambda r: {"mode": r.choice(["RGB", "HSV", "HSL"])},
    "VALTORGB": lambda r: {"positions": sorted(r.random(3).tolist()), "colors": r.random((3, 4)).tolist(),
                           "interpolation": r.choice(["LINEAR", "CONSTANT", "EASE", "B_SPLINE"])},
    "CURVE_RGB": lambda r: {"lut": r.random((256, 4)).tolist()},
    "NORMAL_MAP": lambda r: {"space": r.choice(["TANGENT", "OBJECT", "WORLD"]),
                             "object_matrix": (r.random((3, 3)) * 2 - 1).tolist()},
    "BUMP": lambda r: {"invert": bool(r.integers(2))},
    "VALUE": lambda r: {"value": float(r.normal() * 10)},
    "RGB": lambda r: {"value": r.random(4).tolist()},
}
SOCKETS = ("Value", "Value_001", "Value_002", "Vector", "Vector_001", "Vector_002", "Scale", "Color",
           "Fac", "Factor", "A", "B", "Color1", "Color2", "Gamma", "Bright", "Contrast", "Hue", "Saturation",
           "Strength", "Distance", "Height", "Normal", "X", "Y", "Z", "Red", "Green", "Blue", "Location",
           "Rotation")


def _value(r, nodes):
    pick = r.integers(4)
    if pick == 0 or not nodes:
        return float(r.choice([0.0, -1.0, 1e30, -1e-30, r.normal() * 100]))
    if pick == 1:
        return (r.normal(size=3) * r.choice([1, 1e20])).tolist()
    i = int(r.integers(len(nodes)))
    sockets = NODES[nodes[i]["type"]][1] or {"Is Camera Ray": "f"}
    return {"node": i, "socket": str(r.choice(sorted(sockets)))}


def random_program(r) -> str:
    nodes = []
    for _ in range(int(r.integers(1, 9))):
        kind = str(r.choice(sorted(NODES)))
        inputs = {str(s): _value(r, nodes) for s in r.choice(SOCKETS, size=int(r.integers(0, 5)))}
        nodes.append({"type": kind, "inputs": inputs, "params": PARAMS.get(kind, lambda r: {})(r)})
    outputs = {name: _value(r, nodes) for name in OUTPUTS}
    return json.dumps({"version": 1, "nodes": nodes, "outputs": outputs})


@pytest.mark.parametrize("seed", range(100))
def test_random_programs_evaluate_to_finite_values(seed):
    r = np.random.default_rng(seed)
    tri = r.normal(size=(3, 3, 3))
    uvs = r.normal(size=(3, 3, 2)) * 10
    textures = TextureTable(("a", "b"), (r.random((3, 5, 4)).astype(np.float32), np.ones((1, 1, 4), np.float32)))
    mesh = MeshShading(tri, uvs if seed % 3 else None, None, np.array([0, 1, 1]), textures)
    n = 17
    prim = r.integers(0, 3, n)
    b = r.dirichlet([1, 1, 1], n)
    ng = np.cross(tri[prim, 1] - tri[prim, 0], tri[prim, 2] - tri[prim, 0])
    ng /= np.linalg.norm(ng, axis=1, keepdims=True)
    ctx = mesh.context(prim, b, ng, ng)
    prog, _ = compile_program(random_program(r), "Fuzz", len(textures))
    if prog is None:
        return
    out = prog.evaluate(ctx, list(OUTPUTS))
    for name, value in out.items():
        assert np.isfinite(value).all(), name
