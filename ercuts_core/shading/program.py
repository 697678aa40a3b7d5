"""Shading programs: parse and validate once per material, evaluate over the N hits of one
material at a time (format: :mod:`ercuts_core.shading`).

:func:`compile_program` turns the JSON text into a :class:`Program` or, for a malformed
program or an unsupported node, into ``None`` plus one message naming the material and the
node (the material then renders with its constants). Recoverable oddities (an unknown blend
mode or math operation, a texture row out of range) give a message and a documented
fallback but keep the program.

:meth:`Program.evaluate` runs only the nodes the requested outputs depend on, in the
program's (topological) order, each node vectorized over all hits.
"""
from __future__ import annotations

import json
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..bump_shadowing import MODELS
from .nodes import BLEND_MODES, MATH_OPS, NODES, VECT_MATH_OPS, C, F, V, Inputs, as_float, as_vec

#: Program outputs and their kinds (f: float, c: colour, v: vector).
OUTPUTS = {"base_color": C, "roughness": F, "metallic": F, "specular": F, "emission": C,
           "alpha": F, "normal": V, "transmission": F, "ior": F, "translucency": F}
#: The outputs that parameterise the BSDF.
BSDF_OUTPUTS = ("base_color", "roughness", "metallic", "specular", "transmission", "ior",
                "translucency")


class ProgramError(ValueError):
    """A program cannot be used (the message names the node)."""


@dataclass(frozen=True)
class Ref:
    """A link to output ``socket`` of node ``node``."""

    node: int
    socket: str


@dataclass(frozen=True)
class Const:
    """A constant value: (3,) colour/vector or a float."""

    value: Any
    kind: str


@dataclass(frozen=True)
class Node:
    type: str
    inputs: dict
    params: dict


# ---------------------------------------------------------------------------------------
# Parsing
# ---------------------------------------------------------------------------------------


def _parse_value(raw, i: int, nodes: list[Node], where: str):
    """A <value> of the format → Ref or Const (refs must point backwards)."""
    if isinstance(raw, bool) or raw is None:
        raise ProgramError(f"{where}: value {raw!r} is not a number, vector or link")
    if isinstance(raw, (int, float)):
        if not np.isfinite(raw):
            raise ProgramError(f"{where}: non-finite constant")
        return Const(float(raw), F)
    if isinstance(raw, list):
        if not 1 <= len(raw) <= 4 or not all(isinstance(x, (int, float)) and not isinstance(x, bool)
                                            for x in raw):
            raise ProgramError(f"{where}: constant {raw!r} is not a list of 1 to 4 numbers")
        vals = np.zeros(3)
        vals[:min(3, len(raw))] = raw[:3]
        if not np.isfinite(vals).all():
            raise ProgramError(f"{where}: non-finite constant")
        return Const(vals if len(raw) > 1 else float(raw[0]), C if len(raw) > 1 else F)
    if isinstance(raw, dict):
        node, socket = raw.get("node"), raw.get("socket")
        if not isinstance(node, int) or isinstance(node, bool) or not 0 <= node < i:
            raise ProgramError(f"{where}: link to node {node!r} (links must point to an earlier node)")
        sockets = NODES[nodes[node].type][1]
        if not isinstance(socket, str) or (sockets is not None and socket not in sockets):
            raise ProgramError(f"{where}: node {node} ({nodes[node].type}) has no output {socket!r}")
        return Ref(node, socket)
    raise ProgramError(f"{where}: value {raw!r} is not a number, vector or link")


def _check_params(i: int, node: Node, n_textures: int, notes: list[str]) -> Node:
    """Recoverable parameter problems: a note and the documented fallback."""
    p = dict(node.params)
    label = f"node {i} ({node.type})"
    if node.type == "MATH" and p.get("operation", "ADD") not in MATH_OPS:
        notes.append(f"{label}: math operation {p.get('operation')!r} is not supported, using ADD")
        p["operation"] = "ADD"
    if node.type == "VECT_MATH" and p.get("operation", "ADD") not in VECT_MATH_OPS:
        notes.append(f"{label}: vector math operation {p.get('operation')!r} is not supported, using ADD")
        p["operation"] = "ADD"
    if node.type in ("MIX", "MIX_RGB") and p.get("blend_type", "MIX") not in BLEND_MODES:
        notes.append(f"{label}: blend mode {p.get('blend_type')!r} is not supported, using MIX")
        p["blend_type"] = "MIX"
    if node.type == "TEX_IMAGE":
        tex = p.get("texture", -1)
        if not isinstance(tex, int) or not 0 <= tex < n_textures:
            notes.append(f"{label}: texture {tex!r} is not in the texture table: rendered magenta")
            p["texture"] = -1
    return replace(node, params=p)


def _parse(data, n_textures: int, notes: list[str]) -> "Program":
    if not isinstance(data, dict):
        raise ProgramError("the program is not a JSON object")
    if data.get("version") != 1:
        raise ProgramError(f"program version {data.get('version')!r} (this core reads version 1)")
    raw_nodes = data.get("nodes", [])
    if not isinstance(raw_nodes, list):
        raise ProgramError("'nodes' is not a list")
    nodes: list[Node] = []
    for i, raw in enumerate(raw_nodes):
        if not isinstance(raw, dict) or not isinstance(raw.get("type"), str):
            raise ProgramError(f"node {i} is not an object with a 'type'")
        kind = raw["type"]
        if kind not in NODES:
            raise ProgramError(f"node {i} ({kind}) is not supported")
        inputs, params = raw.get("inputs", {}) or {}, raw.get("params", {}) or {}
        if not isinstance(inputs, dict) or not isinstance(params, dict):
            raise ProgramError(f"node {i} ({kind}): 'inputs' and 'params' must be objects")
        node = Node(kind, {}, params)
        nodes.append(node)
        parsed = {str(k): _parse_value(v, i, nodes, f"node {i} ({kind}) input {k!r}")
                  for k, v in inputs.items()}
        nodes[i] = _check_params(i, replace(node, inputs=parsed), n_textures, notes)
    raw_out = data.get("outputs", {}) or {}
    if not isinstance(raw_out, dict):
        raise ProgramError("'outputs' is not an object")
    outputs = {}
    for name, raw in raw_out.items():
        if name not in OUTPUTS:
            notes.append(f"output {name!r} is not a program output: ignored")
            continue
        if raw is not None:
            outputs[name] = _parse_value(raw, len(nodes), nodes, f"output {name!r}")
    shadowing = data.get("bump_shadowing", "NONE")
    if shadowing not in MODELS:
        notes.append(f"bump_shadowing {shadowing!r} is not a model ({', '.join(MODELS)}): using NONE")
        shadowing = "NONE"
    return Program(tuple(nodes), outputs, MODELS[shadowing])


def compile_program(text: str, material: str, n_textures: int) -> tuple["Program | None", list[str]]:
    """Parse and validate one material's program.

    Returns:
        (program or None, messages). None for "" (constants only) and for unusable programs;
        each message starts with "Material '<name>':" and names the node concerned.
    """
    if not text:
        return None, []
    notes: list[str] = []
    try:
        program = _parse(json.loads(text), n_textures, notes)
    except (ValueError, RecursionError) as exc:   # json.JSONDecodeError and ProgramError
        return None, [f"Material '{material}': shading program unusable ({exc}): using its constant values"]
    return program, [f"Material '{material}': {n}" for n in notes]


# ---------------------------------------------------------------------------------------
# Evaluation
# ---------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Program:
    """A validated program: nodes in topological order, the output values and the
    bump-shadowing model code of its normal output (:mod:`ercuts_core.bump_shadowing`)."""

    nodes: tuple[Node, ...]
    outputs: dict
    bump_shadowing: int = 0

    def closure(self, values) -> list[int]:
        """Sorted indices of the nodes that ``values`` (Refs/Consts) depend on."""
        need: set[int] = set()
        stack = [v.node for v in values if isinstance(v, Ref)]
        while stack:
            i = stack.pop()
            if i in need:
                continue
            need.add(i)
            stack.extend(v.node for v in self.nodes[i].inputs.values() if isinstance(v, Ref))
        return sorted(need)

    def has(self, name: str) -> bool:
        return name in self.outputs

    def _run(self, ctx, values) -> dict[int, dict]:
        """Evaluate the nodes ``values`` depend on; returns {node index: {socket: value}}."""
        results: dict[int, dict] = {}
        n = ctx.n
        for i in self.closure(values):
            node = self.nodes[i]
            inputs = {k: _resolve(v, results, ctx) for k, v in node.inputs.items()}
            fn = NODES[node.type][0]
            node_ctx = ctx
            if node.type == "BUMP":
                node_ctx = replace(ctx, bump_heights=self._bump_heights(ctx, node, inputs))
            with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
                results[i] = fn(Inputs(inputs, n), node.params, node_ctx)
        return results

    def _bump_heights(self, ctx, node: Node, inputs: dict):
        """(h, h_x, h_y, dPdx, dPdy): the Height input at the hit and at two offset points."""
        ctx_x, ctx_y, dpdx, dpdy = ctx.bump_offsets()
        height = node.inputs.get("Height")
        if "Height" not in inputs:
            h = np.ones(ctx.n)
            return h, h, h, dpdx, dpdy
        h = as_float(inputs["Height"])
        hx = as_float(_resolve(height, self._run(ctx_x, [height]), ctx_x))
        hy = as_float(_resolve(height, self._run(ctx_y, [height]), ctx_y))
        return h, hx, hy, dpdx, dpdy

    def evaluate(self, ctx, names) -> dict[str, NDArray]:
        """Values of the program outputs ``names`` present in this program over ``ctx``'s hits:
        floats (N,), colours/vectors (N, 3); 'normal' unit (the context's ns where zero)."""
        present = [name for name in names if name in self.outputs]
        results = self._run(ctx, [self.outputs[name] for name in present])
        out = {}
        for name in present:
            val = _resolve(self.outputs[name], results, ctx)
            arr = as_float(val) if OUTPUTS[name] == F else as_vec(val)
            out[name] = np.where(np.isfinite(arr), arr, 0.0)
        if "normal" in out:
            nrm = out["normal"]
            length = np.linalg.norm(nrm, axis=1)
            unit = nrm / np.maximum(length, 1e-300)[:, None]
            out["normal"] = np.where((length > 1e-12)[:, None], unit, ctx.ns)
        return out


def _resolve(v, results: dict, ctx):
    """An input/output value over the context's hits: (array, kind)."""
    n = ctx.n
    if isinstance(v, Ref):
        outs = results[v.node]
        if v.socket in outs:
            return outs[v.socket]
        return np.zeros(n), F                      # LIGHT_PATH sockets not modelled
    if isinstance(v, LaneConst):
        return v.table[ctx.lane_row], v.kind
    if v.kind == F:
        return np.full(n, v.value), F
    return np.tile(v.value, (n, 1)), v.kind


# ---------------------------------------------------------------------------------------
# Families: programs that differ only in constants, evaluated together
# ---------------------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class LaneConst:
    """A constant that differs between the materials of a family: ``table[lane_row]``
    ((R,) floats or (R, 3) colours/vectors) with ``ctx.lane_row`` the hit's material
    index in the family."""

    table: NDArray
    kind: str


def _value_key(v) -> list:
    return ["ref", v.node, v.socket] if isinstance(v, Ref) else ["const", v.kind]


def signature(program: Program) -> str:
    """The program's structure without its constant inputs and texture rows: programs with
    equal signatures (e.g. every material an importer made from one template) can be
    evaluated as one merged program (:func:`merge`), so the per-node Python overhead is paid once
    per family rather than once per material."""
    nodes = []
    for node in program.nodes:
        params = {k: v for k, v in node.params.items() if not (node.type == "TEX_IMAGE" and k == "texture")}
        nodes.append([node.type, sorted((k, _value_key(v)) for k, v in node.inputs.items()), params])
    outputs = sorted((k, _value_key(v)) for k, v in program.outputs.items())
    return json.dumps([nodes, outputs, program.bump_shadowing], sort_keys=True, default=str)


def _merge_value(values: list):
    first = values[0]
    if isinstance(first, Ref):
        return first
    table = np.array([v.value for v in values], np.float64)
    if (table == table[0]).all():
        return first
    return LaneConst(table, first.kind)


def merge(programs: list[Program]) -> Program:
    """One program for a family of programs with equal :func:`signature`: constants that
    differ become :class:`LaneConst`, TEX_IMAGE texture rows an (R,) int array."""
    base = programs[0]
    nodes = []
    for i, node in enumerate(base.nodes):
        inputs = {k: _merge_value([p.nodes[i].inputs[k] for p in programs]) for k in node.inputs}
        params = dict(node.params)
        if node.type == "TEX_IMAGE":
            rows = np.array([p.nodes[i].params.get("texture", -1) for p in programs], np.int64)
            params["texture"] = int(rows[0]) if (rows == rows[0]).all() else rows
        nodes.append(replace(node, inputs=inputs, params=params))
    outputs = {k: _merge_value([p.outputs[k] for p in programs]) for k in base.outputs}
    return Program(tuple(nodes), outputs, base.bump_shadowing)
