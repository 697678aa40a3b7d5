"""Blender material node trees → shading programs (issue 14; format in ``ercuts_core.shading``).

:func:`compile_material` follows the links from the active Material Output's Surface
input and produces

* the row constants of today's ``MaterialTable`` (exactly today's values when the tree is
  constants only: Principled, Diffuse, Emission with RGB/Value nodes through reroutes), and
* a program (JSON, version 1): value nodes only, in topological order, plus the outputs
  ``base_color, roughness, metallic, specular, emission, alpha, normal`` and, when the
  material transmits anywhere (transmission not the constant 0), ``transmission, ior``
  (opaque materials' programs are as before; their rows say transmission 0), and when it is
  translucent anywhere (a Translucent BSDF reaches the output), ``translucency``. The program
  is ``""`` when every output is a constant, alpha is 1 and there is no normal input.

What the compiler does
----------------------
* Reroutes, muted links (the input's own value), muted nodes (their internal pass-through
  links) and node groups (flattened recursively: a Group Output input maps back to the group
  node's output, a Group Input output to the group node's input in the enclosing tree) are
  resolved away; nothing of them reaches the program.
* Every input of an emitted node is written explicitly: linked inputs as refs, unlinked ones
  as their default values (colours without alpha, as ``[r, g, b]``). Exceptions, documented
  in the format as "not given": the Image Texture's unlinked Vector becomes a ref to a
  ``UVMAP`` node (Cycles' default: the active render UV map) and the Bump node's unlinked
  Normal is omitted (the shading normal).
* Implicit socket conversions are explicit nodes, as Cycles does them: colour → float is the
  luminance (``RGB_TO_BW``), vector → float the average (``VECT_MATH DOT_PRODUCT`` with
  (⅓, ⅓, ⅓)), float → colour/vector a broadcast (``COMBXYZ``). So a ref always has the
  type of the socket or output it feeds: floats for
  roughness/metallic/specular/alpha/transmission/ior/translucency, 3-vectors for
  base_color/emission/normal.
* Closures are reduced here. Each shader socket becomes a set of lobe parameters with an
  opacity α (1 opaque, 0 = Transparent BSDF) and a flag "has a BSDF":

  - Principled: its inputs (3.x/4.x names via :mod:`..compat`); specular = the core's
    ``specular`` (F0 = 0.08·specular; 4.x: ((ior−1)/(ior+1))²·2·level / 0.08); emission =
    colour × strength; alpha; normal; transmission = Transmission Weight (3.x
    "Transmission") and ior = IOR: the core's glass lobe of weight (1 − metallic)·t, as in
    Cycles (3.x's IOR drives only that lobe, so it is read only where something
    transmits; a textured IOR with transmission 0 becomes the default 1.5). 3.x's
    Transmission Roughness: one note when it is used (the glass lobe takes Roughness).
    Coat, sheen, subsurface: one note.
  - Glossy BSDF (and 3.x's Anisotropic BSDF): base colour = Color, roughness = Roughness
    (3.x's 'Sharp' distribution: 0), metallic 1, specular 0.5 (unused at metallic 1).
    Cycles' Glossy has no Fresnel (it reflects Color at every angle); the core's metal has
    F0 = Color with Schlick's rise to white at grazing angles, exact for a white mirror and
    head-on. Roughness ≤ 0.01778 is the core's perfect mirror. Every distribution renders
    as single-scattering GGX: Beckmann / Ashikhmin-Shirley give one note (when rough),
    Multiscatter GGX none (its extra energy at high roughness is the README's lobe gap);
    anisotropy: one note, rendered isotropic.
  - Glass BSDF: base colour = Color, roughness = Roughness ('Sharp': 0), ior = IOR,
    metallic 0, transmission 1 (specular 0.5, unused: the opaque layer has weight 0).
    The core tints the transmission with the colour and leaves the Fresnel reflection
    white; Cycles tints both, so this is exact for white glass only. An IOR outside the
    core's [1, 10] (e.g. < 1 for a bubble) is clamped, with a note. Thin film (4.2+): note.
  - Refraction BSDF: as the Glass BSDF, with one note: Cycles' node refracts all of the
    light (no Fresnel reflection), the core's glass lobe also reflects its Fresnel part
    F_r (≈ 4 % head-on at IOR 1.5, all of it past the critical angle) and transmits
    (1 − F_r)·Color. Only the reflected part differs; no closer mapping exists without a
    transmission-only lobe in the core.
  - Diffuse: colour, normal (roughness 1, metallic 0, specular 0 as today; its own
    roughness — Oren–Nayar — ignored with a note). Emission: colour × strength, black base.
  - Translucent BSDF: base colour = Color, normal, translucency 1 (roughness 1, metallic 0,
    specular 0 as the Diffuse BSDF): the core's translucent lobe, Color/π toward the far side
    (Cycles' ``bsdf_translucent``), exact. In a Mix/Add its weight blends like transmission
    (Mix(Diffuse, Translucent, f) is translucency f; Mix(Glass, Translucent, f) transmission
    1 − f and translucency f: the core's shares add, ``ercuts_core.bsdf``), exact when the
    sides share one colour; differently coloured Diffuse and Translucent BSDFs share the
    blended colour (the total albedo is Cycles', its split between the two sides is not).
  - Transparent BSDF: α = 0 (a tinted one: a note; rendered as white transparency).
  - Mix Shader mix(f, A, B): α = mix(f, αA, αB); every other parameter is blended with
    t = f·αB / α (so a mix with a Transparent BSDF keeps the opaque side's parameters and
    the core's stochastic alpha does the weighting; t = f when αA = αB = 1). A side without
    a BSDF (Emission, Transparent) does not blend the BSDF parameters
    roughness/metallic/specular/transmission/translucency/ior/normal: the other side's are
    used; base
    colours and emission are always blended. The IOR of a mix where one side does not
    transmit (constant transmission 0) is the transmitting side's, else it is blended.
    Exact for diffuse/diffuse, emission and transparency mixes; mixes of two different GGX
    lobes (or of glass and an opaque lobe with different colours) are approximated by one
    lobe with blended parameters (Mix(Diffuse, Glass, 0.3) is Principled transmission 0.3).
  - Add Shader: base colours and emissions add; α = clamp(αA + αB − 1, 0, 1) (Cycles adds
    the transparent weights); roughness/metallic/specular/transmission/translucency/normal
    from the side with a BSDF, the mean of both when both have one (ior as for Mix, at t = ½;
    Add(Diffuse c, Translucent c) is base 2c, clipped to 1, with translucency ½: exact for
    c ≤ ½).
  - Anything else (SSS, Toon, Sheen, Hair, Volume, …):
    one note naming the node and Cycles' grey diffuse (today's policy).
* Value nodes follow the table of ``ercuts_core.shading``. Map Range (float, linear) and
  Clamp are compiled into MATH nodes. Texture Coordinate Object / Generated / Normal are
  made exact per object: the core's TEX_COORD gives the world position / normal, the
  exporter maps them into the object's space (its matrix; Generated: its texture space;
  Object: the node's other object if set) with DOT_PRODUCT/COMBXYZ/ADD nodes, and such
  materials get one row per object (as object-space Normal Maps, whose ``object_matrix``
  is the object's 3×3 world matrix). Any other node (procedural textures, attributes, …)
  or an unsupported output socket (Texture Coordinate Camera/Window/Reflection, Light
  Path's other outputs) gives one note naming the node and the input's own value.
* A value linked into a shader socket is an Emission, as Cycles converts it (a float its
  strength, a colour its colour).
* Cycles' Image Texture outputs an associated (premultiplied) colour when its Alpha output
  is not linked (nodes.cpp: ``NODE_IMAGE_ALPHA_UNASSOCIATE`` only when Alpha is used);
  the node then reads the image's associated-alpha texture row (:mod:`.images`).
* A link cycle (or a group containing itself) is cut where it closes: one note, and the
  socket's default value there.
"""
from __future__ import annotations

import json
from dataclasses import dataclass, field

import numpy as np

from .. import compat

VERSION = 1
#: Cycles' default surface (unsupported shaders): grey diffuse.
GREY = (0.8, 0.8, 0.8)
#: Luminance of linear Rec.709 (Blender's default OCIO config, Cycles' rgb_to_y).
LUMA = (0.2126729, 0.7151522, 0.0721750)
#: The core's glass-lobe IOR when nothing sets one (``MaterialTable.ior``'s default).
DEFAULT_IOR = 1.5
#: The core's accepted IOR range (``ercuts_core.bsdf.IOR_MIN/IOR_MAX``, rounded).
IOR_RANGE = (1.0, 10.0)
#: BSDF parameters of a :class:`Closure`: blended by Mix/Add only between sides with a BSDF.
BSDF_PARAMS = ("roughness", "metallic", "specular", "transmission", "translucency")
#: Nesting limit for node groups (a deeper stack is reported as a cycle).
MAX_GROUP_DEPTH = 32

#: Supported value nodes: node.type → (program type, {Blender output name: program output}).
_OUTPUTS = {
    "TEX_IMAGE": ("TEX_IMAGE", {"Color": "Color", "Alpha": "Alpha"}),
    "TEX_COORD": ("TEX_COORD", {"UV": "UV", "Generated": "Generated", "Object": "Object",
                                "Normal": "Normal"}),
    "UVMAP": ("UVMAP", {"UV": "UV"}),
    "MAPPING": ("MAPPING", {"Vector": "Vector"}),
    "SEPARATE_COLOR": ("SEPARATE_COLOR", {"Red": "Red", "Green": "Green", "Blue": "Blue"}),
    "SEPRGB": ("SEPARATE_COLOR", {"R": "Red", "G": "Green", "B": "Blue"}),
    "SEPHSV": ("SEPARATE_COLOR", {"H": "Red", "S": "Green", "V": "Blue"}),
    "COMBINE_COLOR": ("COMBINE_COLOR", {"Color": "Color"}),
    "COMBRGB": ("COMBINE_COLOR", {"Image": "Color"}),
    "COMBHSV": ("COMBINE_COLOR", {"Color": "Color"}),
    "SEPXYZ": ("SEPXYZ", {"X": "X", "Y": "Y", "Z": "Z"}),
    "COMBXYZ": ("COMBXYZ", {"Vector": "Vector"}),
    "MIX": ("MIX", {"Result": "Result"}),
    "MIX_RGB": ("MIX", {"Color": "Result"}),
    "MATH": ("MATH", {"Value": "Value"}),
    "VECT_MATH": ("VECT_MATH", {"Vector": "Vector", "Value": "Value"}),
    "INVERT": ("INVERT", {"Color": "Color"}),
    "GAMMA": ("GAMMA", {"Color": "Color"}),
    "BRIGHTCONTRAST": ("BRIGHTCONTRAST", {"Color": "Color"}),
    "HUE_SAT": ("HUE_SAT", {"Color": "Color"}),
    "VALTORGB": ("VALTORGB", {"Color": "Color", "Alpha": "Alpha"}),
    "CURVE_RGB": ("CURVE_RGB", {"Color": "Color"}),
    "RGBTOBW": ("RGB_TO_BW", {"Val": "Val"}),
    "NORMAL_MAP": ("NORMAL_MAP", {"Normal": "Normal"}),
    "BUMP": ("BUMP", {"Normal": "Normal"}),
    # compiled into MATH nodes by the exporter (not program node types of their own)
    "MAP_RANGE": ("MATH", {"Result": "Value"}),
    "CLAMP": ("MATH", {"Result": "Value"}),
    "LIGHT_PATH": ("LIGHT_PATH", {"Is Camera Ray": "Is Camera Ray",
                                  "Is Shadow Ray": "Is Shadow Ray"}),
}
#: Legacy (3.x) input names → the program's (4.x/5.x) names.
_INPUT_RENAMES = {
    "MIX_RGB": {"Fac": "Factor", "Color1": "A", "Color2": "B"},
    "SEPRGB": {"Image": "Color"},
    "COMBRGB": {"R": "Red", "G": "Green", "B": "Blue"},
    "COMBHSV": {"H": "Red", "S": "Green", "V": "Blue"},
}
_COLOR_MODE = {"SEPRGB": "RGB", "SEPHSV": "HSV", "COMBRGB": "RGB", "COMBHSV": "HSV"}
#: Node types whose input keys are socket identifiers (their names repeat).
_BY_IDENTIFIER = {"MATH", "VECT_MATH"}
_SHADERS_GREY = "rendered as grey diffuse"


def is_ref(v) -> bool:
    return isinstance(v, dict)


def _vec3(v) -> tuple:
    return tuple(float(x) for x in v)


def _socket_kind(socket) -> str:
    """'F' (float-like), 'C' (colour), 'V' (vector) or 'S' (shader/other)."""
    t = socket.type
    if t in {"VALUE", "INT", "BOOLEAN"}:
        return "F"
    if t == "RGBA":
        return "C"
    if t == "VECTOR":
        return "V"
    return "S"


def _default(socket, kind=None):
    """A socket's own value in program form (colours without alpha)."""
    kind = kind or _socket_kind(socket)
    value = getattr(socket, "default_value", None)
    if value is None:
        return 0.0 if kind == "F" else (0.0, 0.0, 0.0)
    try:
        seq = tuple(value)
    except TypeError:
        return float(value)
    if kind == "F":
        return float(np.mean(seq[:3])) if seq else 0.0
    return _vec3((tuple(seq) + (0.0, 0.0, 0.0))[:3])


def _name(node) -> str:
    return node.name


@dataclass
class Closure:
    """A shader socket reduced to lobe parameters (constants or refs)."""

    base_color: object = (0.0, 0.0, 0.0)
    roughness: object = 1.0
    metallic: object = 0.0
    specular: object = 0.0
    emission: object = (0.0, 0.0, 0.0)
    alpha: object = 1.0
    normal: object = None
    has_bsdf: bool = False
    transmission: object = 0.0
    ior: object = DEFAULT_IOR
    translucency: object = 0.0


@dataclass
class Compiled:
    """Result of :func:`compile_material`.

    Attributes:
        constants: the row's values (base_color, roughness, metallic, specular, emission,
            transmission, ior, translucency);
            outputs that are refs get an estimate (image means, socket values).
        program: JSON string, or "" when the row's constants say everything.
        notes: what could not be translated (one entry per node/issue).
        uses_uvs / uses_tangents: the program reads ``MeshTable.uvs`` / ``.tangents``.
        uv_maps: UV map names that UV Map / Normal Map nodes ask for ("" = active render).
        needs_object_matrix: per-object nodes (Texture Coordinate Object/Generated/Normal,
            object-space Normal Map): compile again per object with an :class:`ObjectSpace`.
    """

    constants: dict
    program: str = ""
    notes: list = field(default_factory=list)
    uses_uvs: bool = False
    uses_tangents: bool = False
    uv_maps: set = field(default_factory=set)
    needs_object_matrix: bool = False


class _Compiler:
    def __init__(self, material_name: str, textures=None, space: "ObjectSpace | None" = None):
        self.material_name = material_name
        self.textures = textures
        self.space = space
        self.nodes: list[dict] = []
        self.notes: list[str] = []
        self.uses_uvs = False
        self.uses_tangents = False
        self.uv_maps: set[str] = set()
        self.needs_object_matrix = False
        self._cse: dict[str, int] = {}
        self._memo: dict = {}
        self._busy: set = set()
        self._estimates: dict[int, dict] = {}  # node index → {socket: constant estimate}

    # ------------------------------------------------------------------ bookkeeping
    def note(self, text: str) -> None:
        if text not in self.notes:
            self.notes.append(text)

    def emit(self, ntype: str, inputs: dict, params: dict | None = None) -> int:
        """Append a node (or reuse an identical one) and return its index."""
        node = {"type": ntype, "inputs": {k: _jsonable(v) for k, v in inputs.items()},
                "params": params or {}}
        key = json.dumps(node, sort_keys=True)
        index = self._cse.get(key)
        if index is None:
            index = len(self.nodes)
            self.nodes.append(node)
            self._cse[key] = index
        return index

    # ------------------------------------------------------------------ link following
    def upstream(self, socket, ctx):
        """Resolve reroutes, muted nodes and groups: ('const', value) or ('node', node, out, ctx)."""
        kind = _socket_kind(socket)
        for _ in range(4096):
            if not socket.is_linked:
                return "const", _default(socket, kind), None, ctx
            link = socket.links[0]
            if not link.is_valid:
                self.note(f"invalid link from '{link.from_node.name}' to '{link.to_node.name}' "
                          f"(a cycle or incompatible sockets) ignored")
                return "const", _default(socket, kind), None, ctx
            if getattr(link, "is_muted", False):
                return "const", _default(socket, kind), None, ctx
            node, out = link.from_node, link.from_socket
            ntype = node.type
            if ntype == "REROUTE":
                socket = node.inputs[0]
                continue
            if node.mute:
                through = next((il.from_socket for il in node.internal_links
                                if il.to_socket == out), None)
                if through is None:
                    return "const", _default(out, kind), None, ctx
                socket = through
                continue
            if ntype == "GROUP_INPUT":
                if not ctx:
                    return "const", _default(out, kind), None, ctx
                group = ctx[-1]
                target = _by_identifier(group.inputs, out.identifier)
                if target is None:
                    return "const", _default(out, kind), None, ctx
                socket, ctx = target, ctx[:-1]
                continue
            if ntype == "GROUP":
                tree = node.node_tree
                if tree is None:
                    self.note(f"node group '{node.name}' has no node tree, using the input's own value")
                    return "const", _default(socket, kind), None, ctx
                if len(ctx) >= MAX_GROUP_DEPTH or any(g.node_tree == tree for g in ctx):
                    self.note(f"node group '{node.name}' contains itself (a cycle), "
                              f"using the input's own value")
                    return "const", _default(socket, kind), None, ctx
                gout = _group_output(tree)
                target = None if gout is None else _by_identifier(gout.inputs, out.identifier)
                if target is None:
                    return "const", _default(out, kind), None, ctx
                socket, ctx = target, ctx + (node,)
                continue
            return "node", node, out, ctx
        self.note("node links too deep (a cycle?), using the input's own value")
        return "const", _default(socket, kind), None, ctx

    # ------------------------------------------------------------------ values
    def value(self, socket, ctx, want: str | None = None):
        """The program value of an input socket, converted to ``want`` ('F' or 'C'/'V')."""
        want = want or _socket_kind(socket)
        what, a, b, c = self.upstream(socket, ctx)
        if what == "const":
            return _convert_const(a, _const_kind(a), want)
        node, out, nctx = a, b, c
        key = (tuple(g.as_pointer() for g in nctx), node.as_pointer(), out.identifier)
        if key in self._busy:
            self.note(f"node '{node.name}' is part of a link cycle, using the input's own value")
            return _convert_const(_default(socket), _socket_kind(socket), want)
        result = self._memo.get(key)
        if result is None:
            self._busy.add(key)
            try:
                result = self._node_output(node, out, nctx, socket)
            finally:
                self._busy.discard(key)
            if is_ref(result[0]) or node.type in {"RGB", "VALUE"}:
                self._memo[key] = result   # fallbacks depend on the input socket: not memoised
        val, kind = result
        return self.convert(val, kind, want)

    def convert(self, val, kind: str, want: str):
        if not is_ref(val):
            return _convert_const(val, kind, want)
        if kind == want or (kind in "CV" and want in "CV") or want == "S":
            return val
        if want == "F":
            if kind == "C":
                return self.ref("RGB_TO_BW", {"Color": val}, "Val")
            third = 1.0 / 3.0
            return self.ref("VECT_MATH", {"Vector": val, "Vector_001": [third] * 3,
                                          "Vector_002": [0.0] * 3, "Scale": 1.0},
                            "Value", {"operation": "DOT_PRODUCT"})
        return self.ref("COMBXYZ", {"X": val, "Y": val, "Z": val}, "Vector")

    def ref(self, ntype, inputs, socket, params=None) -> dict:
        return {"node": self.emit(ntype, inputs, params), "socket": socket}

    def _node_output(self, node, out, ctx, into):
        """(value, kind) of output ``out`` of a value node."""
        ntype = node.type
        if ntype == "RGB":
            return _vec3(tuple(out.default_value)[:3]), "C"
        if ntype == "VALUE":
            return float(out.default_value), "F"
        kind = _socket_kind(out)
        spec = _OUTPUTS.get(ntype)
        if kind == "S":
            self.note(f"shader output of '{node.name}' linked into value input '{into.name}', "
                      f"using the input's own value")
            return _default(into), _socket_kind(into)
        if spec is None:
            self.note(f"input '{into.name}' linked to unsupported node '{node.name}' "
                      f"({node.bl_idname}), using the input's own value")
            return _default(into), _socket_kind(into)
        ptype, outputs = spec
        if out.name not in outputs:
            self.note(f"output '{out.name}' of node '{node.name}' ({node.bl_idname}) is not "
                      f"supported, using the input's own value")
            return _default(into), _socket_kind(into)
        psocket = outputs[out.name]
        handler = getattr(self, "_n_" + ntype.lower(), None)
        if handler is not None:
            result = handler(node, out, ctx, ptype, psocket)
            if result is not None:
                return result, kind
            return _default(into), _socket_kind(into)
        inputs = self.inputs_of(node, ctx)
        params = self.params_of(node)
        return self.ref(ptype, inputs, psocket, params), kind

    def inputs_of(self, node, ctx, skip=()) -> dict:
        renames = _INPUT_RENAMES.get(node.type, {})
        by_id = node.type in _BY_IDENTIFIER
        inputs = {}
        for sock in node.inputs:
            if not getattr(sock, "enabled", True) or _socket_kind(sock) == "S":
                continue
            key = sock.identifier if by_id else renames.get(sock.name, sock.name)
            if key in skip:
                continue
            inputs[key] = self.value(sock, ctx)
        return inputs

    def params_of(self, node) -> dict:
        t = node.type
        if t == "MAPPING":
            return {"vector_type": node.vector_type}
        if t in {"SEPARATE_COLOR", "COMBINE_COLOR"}:
            return {"mode": node.mode}
        if t in _COLOR_MODE:
            return {"mode": _COLOR_MODE[t]}
        if t == "MIX":
            return {"data_type": node.data_type, "blend_type": node.blend_type,
                    "clamp_factor": bool(node.clamp_factor), "clamp_result": bool(node.clamp_result),
                    "factor_mode": getattr(node, "factor_mode", "UNIFORM")}
        if t == "MIX_RGB":
            return {"data_type": "RGBA", "blend_type": node.blend_type, "clamp_factor": True,
                    "clamp_result": bool(node.use_clamp), "factor_mode": "UNIFORM"}
        if t == "MATH":
            return {"operation": node.operation, "use_clamp": bool(node.use_clamp)}
        if t == "VECT_MATH":
            return {"operation": node.operation}
        if t == "BUMP":
            return {"invert": bool(node.invert)}
        return {}

    # ------------------------------------------------------------------ special value nodes
    def uvmap(self) -> dict:
        self.uses_uvs = True
        return self.ref("UVMAP", {}, "UV")

    def _n_uvmap(self, node, out, ctx, ptype, psocket):
        if getattr(node, "from_instancer", False):
            self.note(f"UV Map '{node.name}': 'From Instancer' ignored")
        self.uv_maps.add(node.uv_map)
        return self.uvmap()

    def _n_tex_coord(self, node, out, ctx, ptype, psocket):
        """UV from the UV map; Object, Generated and Normal per object (``self.space``): the
        core's TEX_COORD gives the world position / shading normal, the exporter maps them
        into the object's space with the object's matrix and texture space (one row per
        object, :meth:`..materials.MaterialCollector.slot_table`)."""
        if psocket == "UV":
            return self.uvmap()
        self.needs_object_matrix = True
        if self.space is None:
            return self.ref("TEX_COORD", {}, psocket)
        sp = self.space
        if psocket == "Normal":  # object-space normal: normalize(Mᵀ n)
            m3 = sp.world_from_object[:3, :3]
            return self.normalize(self.affine(self.ref("TEX_COORD", {}, "Normal"), m3.T, None))
        m = sp.world_from_object
        if psocket == "Object" and node.object is not None:
            m = sp.matrix_of(node.object)
        inv = np.linalg.inv(m)
        linear, offset = inv[:3, :3], inv[:3, 3]
        if psocket == "Generated":
            # Blender: (co − (L − S)) / 2S with the texture space location L and size S
            # (a zero size counts as 1, as BKE_mesh_texspace_calc does)
            size = np.where(np.abs(sp.texspace_size) > 0, sp.texspace_size, 1.0)
            k = 1.0 / (2.0 * size)
            linear = k[:, None] * linear
            offset = k * (offset - (np.asarray(sp.texspace_location) - size))
        return self.affine(self.ref("TEX_COORD", {}, "Object"), linear, offset)

    def affine(self, v, linear, offset):
        """``linear @ v + offset`` with value nodes (3 dot products, COMBXYZ, ADD)."""
        rows = [self.ref("VECT_MATH", {"Vector": v, "Vector_001": [float(x) for x in row],
                                       "Vector_002": [0.0] * 3, "Scale": 1.0}, "Value",
                         {"operation": "DOT_PRODUCT"}) for row in np.asarray(linear, float)]
        out = self.ref("COMBXYZ", {"X": rows[0], "Y": rows[1], "Z": rows[2]}, "Vector")
        if offset is None or not np.any(offset):
            return out
        return self.add(out, _vec3(offset), "V")

    def math(self, op: str, a, b, clamp: bool = False):
        return self.ref("MATH", {"Value": a, "Value_001": b, "Value_002": 0.0}, "Value",
                        {"operation": op, "use_clamp": clamp})

    def _enabled(self, node, name, ctx):
        sock = next(s for s in node.inputs if s.name == name and getattr(s, "enabled", True))
        return self.value(sock, ctx, "F")

    def _n_map_range(self, node, out, ctx, ptype, psocket):
        """Map Range (float, linear): to_min + f·(to_max − to_min), f = (v − from_min) /
        (from_max − from_min) (0 when the range is empty, Cycles' safe division), f clamped
        to [0, 1] when Clamp is on (the same as clamping the result)."""
        if node.data_type != "FLOAT" or node.interpolation_type != "LINEAR":
            self.note(f"Map Range '{node.name}': {node.data_type.lower()} "
                      f"{node.interpolation_type.lower()} mapping not supported, using the input's "
                      f"own value")
            return None
        v, f0, f1, t0, t1 = (self._enabled(node, n, ctx) for n in
                             ("Value", "From Min", "From Max", "To Min", "To Max"))
        f = self.math("DIVIDE", self.math("SUBTRACT", v, f0), self.math("SUBTRACT", f1, f0),
                      clamp=bool(node.clamp))
        return self.math("ADD", t0, self.math("MULTIPLY", f, self.math("SUBTRACT", t1, t0)))

    def _n_clamp(self, node, out, ctx, ptype, psocket):
        """Clamp: MINMAX min(max(v, lo), hi); RANGE the same with lo/hi sorted."""
        v, lo, hi = (self._enabled(node, n, ctx) for n in ("Value", "Min", "Max"))
        if node.clamp_type == "RANGE":
            lo, hi = self.math("MINIMUM", lo, hi), self.math("MAXIMUM", lo, hi)
        return self.math("MINIMUM", self.math("MAXIMUM", v, lo), hi)

    def _n_light_path(self, node, out, ctx, ptype, psocket):
        self.note(f"Light Path '{node.name}': '{out.name}' evaluated as "
                  f"{'1' if psocket == 'Is Camera Ray' else '0'} on every ray")
        return self.ref("LIGHT_PATH", {}, psocket)

    def _n_tex_image(self, node, out, ctx, ptype, psocket):
        image = node.image
        vector = node.inputs["Vector"]
        coords = self.value(vector, ctx) if _linked(vector) else self.uvmap()
        if node.projection != "FLAT":
            self.note(f"Image Texture '{node.name}': {node.projection.lower()} projection "
                      f"rendered as flat")
        interpolation = {"Smart": "Cubic"}.get(node.interpolation, node.interpolation)
        if image is None:  # measured with Cycles 5.0.1: magenta, alpha 1
            self.note(f"Image Texture '{node.name}' has no image: rendered magenta")
            return (1.0, 0.0, 1.0) if psocket == "Color" else 1.0
        # Cycles: Color is associated (premultiplied) unless the Alpha output is used.
        associated = not _linked(node.outputs["Alpha"])
        if self.textures is None:
            row, info = 0, None
        else:
            row, info = self.textures.index_of(image, self.material_name, associated)
        if image.source in {"SEQUENCE", "MOVIE", "TILED"}:
            self.note(f"Image Texture '{node.name}': {image.source.lower()} image "
                      f"'{image.name}', using its first frame/tile")
        params = {"texture": int(row), "interpolation": interpolation,
                  "extension": node.extension}
        result = self.ref("TEX_IMAGE", {"Vector": coords}, psocket, params)
        if info is not None:
            self._estimates[result["node"]] = {"Color": info.mean_color, "Alpha": info.mean_alpha}
        return result

    def _n_valtorgb(self, node, out, ctx, ptype, psocket):
        ramp = node.color_ramp
        if getattr(ramp, "color_mode", "RGB") != "RGB":
            self.note(f"Color Ramp '{node.name}': {ramp.color_mode} interpolation done in RGB")
        params = {"positions": [float(e.position) for e in ramp.elements],
                  "colors": [[float(c) for c in e.color] for e in ramp.elements],
                  "interpolation": ramp.interpolation}
        return self.ref("VALTORGB", self.inputs_of(node, ctx), psocket, params)

    def _n_curve_rgb(self, node, out, ctx, ptype, psocket):
        mapping = node.mapping
        try:
            mapping.initialize()
            xs = np.linspace(0.0, 1.0, 256)
            curves = mapping.curves  # R, G, B, C
            lut = [[float(mapping.evaluate(curves[i], float(x))) for i in (3, 0, 1, 2)] for x in xs]
        except (RuntimeError, AttributeError, IndexError) as exc:
            self.note(f"RGB Curves '{node.name}': could not be sampled ({exc}), passed through")
            return self.value(node.inputs["Color"], ctx, "C")
        if tuple(mapping.black_level)[:3] != (0, 0, 0) or tuple(mapping.white_level)[:3] != (1, 1, 1):
            self.note(f"RGB Curves '{node.name}': black/white levels ignored")
        return self.ref("CURVE_RGB", self.inputs_of(node, ctx), psocket, {"lut": lut})

    def _n_normal_map(self, node, out, ctx, ptype, psocket):
        params = {"space": node.space}
        if node.space in {"BLENDER_OBJECT", "BLENDER_WORLD"}:
            params["space"] = node.space.replace("BLENDER_", "")
            self.note(f"Normal Map '{node.name}': Blender-convention {node.space.lower()} space "
                      f"read as {params['space'].lower()} space")
        if params["space"] == "TANGENT":
            self.uses_tangents = True
            self.uses_uvs = True
            self.uv_maps.add(node.uv_map)
        elif params["space"] == "OBJECT":
            self.needs_object_matrix = True  # compiled again per object (materials.py)
            if self.space is not None:
                params["object_matrix"] = self.space.world_from_object[:3, :3].tolist()
        return self.ref("NORMAL_MAP", self.inputs_of(node, ctx), psocket, params)

    def _n_bump(self, node, out, ctx, ptype, psocket):
        normal = node.inputs.get("Normal")
        inputs = self.inputs_of(node, ctx, skip=() if _linked(normal) else ("Normal",))
        return self.ref("BUMP", inputs, psocket, self.params_of(node))

    # ------------------------------------------------------------------ closures
    def shader(self, socket, ctx, depth=0) -> Closure:
        what, a, b, c = self.upstream(socket, ctx)
        if what == "const":  # nothing connected: no closure (black, opaque)
            return Closure(base_color=(0.0, 0.0, 0.0), specular=0.0)
        node, out, nctx = a, b, c
        if _socket_kind(out) != "S":
            # Cycles turns a value linked into a shader socket into an Emission: a float
            # drives its strength (white), a colour/vector its colour (strength 1).
            value = self.value(socket, ctx)
            if _socket_kind(out) == "F":
                return Closure(base_color=(0.0, 0.0, 0.0), emission=self.scale((1.0, 1.0, 1.0), value))
            return Closure(base_color=(0.0, 0.0, 0.0), emission=self.convert(value, "C", "C"))
        key = ("S", tuple(g.as_pointer() for g in nctx), node.as_pointer())
        if key in self._busy or depth > 256:
            self.note(f"shader '{node.name}' is part of a link cycle, rendered as black")
            return Closure(base_color=(0.0, 0.0, 0.0))
        self._busy.add(key)
        try:
            return self._shader_node(node, nctx, depth)
        finally:
            self._busy.discard(key)

    def _shader_node(self, node, ctx, depth) -> Closure:
        t = node.type
        if t == "BSDF_PRINCIPLED":
            return self._principled(node, ctx)
        if t in {"BSDF_GLOSSY", "BSDF_ANISOTROPIC"}:
            return self._glossy(node, ctx)
        if t in {"BSDF_GLASS", "BSDF_REFRACTION"}:
            return self._glass(node, ctx)
        if t == "BSDF_DIFFUSE":
            rough = node.inputs.get("Roughness")
            if rough is not None and (_linked(rough) or float(rough.default_value) > 0.0):
                self.note("Diffuse BSDF roughness (Oren-Nayar) ignored, rendered as Lambert")
            return Closure(base_color=self.value(node.inputs["Color"], ctx, "C"),
                           normal=self.normal(node.inputs.get("Normal"), ctx), has_bsdf=True)
        if t == "BSDF_TRANSLUCENT":
            return Closure(base_color=self.value(node.inputs["Color"], ctx, "C"),
                           normal=self.normal(node.inputs.get("Normal"), ctx), has_bsdf=True,
                           translucency=1.0)
        if t == "EMISSION":
            color = self.value(node.inputs["Color"], ctx, "C")
            strength = self.value(node.inputs["Strength"], ctx, "F")
            return Closure(base_color=(0.0, 0.0, 0.0), emission=self.scale(color, strength))
        if t == "BSDF_TRANSPARENT":
            color = node.inputs["Color"]
            if _linked(color) or _default(color) != (1.0, 1.0, 1.0):
                self.note(f"Transparent BSDF '{node.name}': tint ignored (white transparency)")
            return Closure(base_color=(0.0, 0.0, 0.0), alpha=0.0)
        if t == "MIX_SHADER":
            fac = self.value(node.inputs[0], ctx, "F")
            a = self.shader(node.inputs[1], ctx, depth + 1)
            b = self.shader(node.inputs[2], ctx, depth + 1)
            return self.mix_closures(fac, a, b)
        if t == "ADD_SHADER":
            a = self.shader(node.inputs[0], ctx, depth + 1)
            b = self.shader(node.inputs[1], ctx, depth + 1)
            return self.add_closures(a, b)
        self.note(f"unsupported shader '{node.name}' ({node.bl_idname}), {_SHADERS_GREY}")
        return Closure(base_color=GREY, has_bsdf=True)

    def normal(self, socket, ctx):
        if socket is None or not _linked(socket):
            return None
        what = self.upstream(socket, ctx)[0]
        if what == "const":
            return None
        return self.value(socket, ctx, "V")

    def _principled(self, node, ctx) -> Closure:
        get = lambda concept: compat.principled_input(node, concept)  # noqa: E731
        for concept, label in (("coat", "coat"), ("sheen", "sheen"), ("subsurface", "subsurface")):
            s = get(concept)
            if s is not None and (_linked(s) or float(s.default_value) > 0.0):
                self.note(f"Principled {label} ignored")
        base = self.value(get("base_color"), ctx, "C")
        roughness = self.value(get("roughness"), ctx, "F")
        metallic = self.value(get("metallic"), ctx, "F")
        level = self.value(get("specular"), ctx, "F")
        transmission = self._weight(get("transmission"), ctx)
        # 3.x: IOR drives the glass lobe only (not read where nothing transmits)
        ior = (self.value(get("ior"), ctx, "F") if compat.PRINCIPLED_V4 or transmission != 0.0
               else DEFAULT_IOR)
        if transmission != 0.0:
            t_rough = get("transmission_roughness")   # 3.x only
            if t_rough is not None and (_linked(t_rough) or float(t_rough.default_value) > 0.0):
                self.note(f"Principled '{node.name}': Transmission Roughness ignored "
                          f"(the glass lobe uses Roughness)")
            self._check_ior(node, ior)
        if compat.PRINCIPLED_V4:
            if is_ref(ior):  # ((ior-1)/(ior+1))² · 2 / 0.08 · level
                f = self.div(self.sub(ior, 1.0), self.add(ior, 1.0, "F"))
                f = self.mul(self.mul(f, f), 25.0)
                specular = self.mul(f, level)
            else:
                specular = self.mul(compat.principled_specular(1.0, ior), level)
        else:
            specular = level
        e_color = self.value(get("emission_color"), ctx, "C")
        e_strength = self.value(get("emission_strength"), ctx, "F")
        alpha = self.value(get("alpha"), ctx, "F") if get("alpha") is not None else 1.0
        if not is_ref(alpha):
            alpha = min(max(alpha, 0.0), 1.0)
        return Closure(base_color=base, roughness=roughness, metallic=metallic, specular=specular,
                       emission=self.scale(e_color, e_strength), alpha=alpha,
                       normal=self.normal(get("normal"), ctx), has_bsdf=True,
                       transmission=transmission, ior=self._glass_ior(transmission, ior))

    def _weight(self, socket, ctx):
        """A [0, 1] weight input (constants clamped; None → 0)."""
        if socket is None:
            return 0.0
        v = self.value(socket, ctx, "F")
        return v if is_ref(v) else _clip01(v)

    @staticmethod
    def _glass_ior(transmission, ior):
        """The glass lobe's IOR: a textured IOR only matters where something transmits."""
        if not is_ref(transmission) and transmission == 0.0 and is_ref(ior):
            return DEFAULT_IOR
        return ior

    def _check_ior(self, node, ior):
        if not is_ref(ior) and not IOR_RANGE[0] <= ior <= IOR_RANGE[1]:
            lo, hi = IOR_RANGE
            self.note(f"'{node.name}': IOR {ior:g} outside [{lo:g}, {hi:g}], "
                      f"rendered as {min(max(ior, lo), hi):g}")

    def _microfacet_roughness(self, node, ctx, kind: str):
        """Roughness of a Glossy/Anisotropic/Glass/Refraction node (3.x 'Sharp': 0), with a
        note for a distribution the core does not have (it has GGX only)."""
        dist = getattr(node, "distribution", "GGX")
        if dist == "SHARP":
            return 0.0
        roughness = self.value(node.inputs["Roughness"], ctx, "F")
        if dist in {"BECKMANN", "ASHIKHMIN_SHIRLEY"} and (is_ref(roughness) or roughness > 0.0):
            label = {"BECKMANN": "Beckmann", "ASHIKHMIN_SHIRLEY": "Ashikhmin-Shirley"}[dist]
            self.note(f"{kind} '{node.name}': {label} distribution rendered as GGX")
        return roughness

    def _glossy(self, node, ctx) -> Closure:
        """Glossy (and 3.x Anisotropic) BSDF: a metal with F0 = Color (no Fresnel in Cycles'
        node; the core's metallic Schlick curve rises to white at grazing angles only)."""
        kind = "Anisotropic BSDF" if node.type == "BSDF_ANISOTROPIC" else "Glossy BSDF"
        roughness = self._microfacet_roughness(node, ctx, kind)
        aniso = node.inputs.get("Anisotropy")
        if aniso is not None and roughness != 0.0 and (
                _linked(aniso) or float(aniso.default_value) != 0.0):
            self.note(f"{kind} '{node.name}': anisotropy ignored (isotropic GGX)")
        return Closure(base_color=self.value(node.inputs["Color"], ctx, "C"), roughness=roughness,
                       metallic=1.0, specular=0.5, normal=self.normal(node.inputs.get("Normal"), ctx),
                       has_bsdf=True)

    def _glass(self, node, ctx) -> Closure:
        """Glass and Refraction BSDF: the core's glass lobe (transmission 1, metallic 0)."""
        kind = "Glass BSDF" if node.type == "BSDF_GLASS" else "Refraction BSDF"
        roughness = self._microfacet_roughness(node, ctx, kind)
        ior = self.value(node.inputs["IOR"], ctx, "F")
        self._check_ior(node, ior)
        film = node.inputs.get("Thin Film Thickness")   # 4.2+
        if film is not None and (_linked(film) or float(film.default_value) > 0.0):
            self.note(f"{kind} '{node.name}': thin film ignored")
        if node.type == "BSDF_REFRACTION":
            self.note(f"Refraction BSDF '{node.name}' rendered as Glass BSDF "
                      f"(its Fresnel reflection is kept)")
        return Closure(base_color=self.value(node.inputs["Color"], ctx, "C"), roughness=roughness,
                       metallic=0.0, specular=0.5, normal=self.normal(node.inputs.get("Normal"), ctx),
                       has_bsdf=True, transmission=1.0, ior=ior)

    # ------------------------------------------------------------------ arithmetic with folding
    def mul(self, a, b):
        if not is_ref(a) and not is_ref(b):
            return float(a) * float(b)
        if not is_ref(a) and float(a) == 1.0:
            return b
        if not is_ref(b) and float(b) == 1.0:
            return a
        return self.ref("MATH", {"Value": a, "Value_001": b, "Value_002": 0.0}, "Value",
                        {"operation": "MULTIPLY", "use_clamp": False})

    def sub(self, a, b):
        return self.ref("MATH", {"Value": a, "Value_001": b, "Value_002": 0.0}, "Value",
                        {"operation": "SUBTRACT", "use_clamp": False})

    def div(self, a, b):
        return self.ref("MATH", {"Value": a, "Value_001": b, "Value_002": 0.0}, "Value",
                        {"operation": "DIVIDE", "use_clamp": False})

    def scale(self, color, strength):
        if not is_ref(color) and not is_ref(strength):
            return _vec3(np.asarray(color) * float(strength))
        if not is_ref(strength) and float(strength) == 1.0:
            return color
        if not is_ref(strength) and float(strength) == 0.0:
            return (0.0, 0.0, 0.0)
        if not is_ref(color) and max(color) == min(color) == 0.0:
            return (0.0, 0.0, 0.0)
        return self.ref("VECT_MATH", {"Vector": _jsonable(color), "Vector_001": [0.0] * 3,
                                      "Vector_002": [0.0] * 3, "Scale": strength},
                        "Vector", {"operation": "SCALE"})

    def mix(self, f, a, b, kind: str):
        if a == b:
            return a
        if not is_ref(f):
            f = min(max(float(f), 0.0), 1.0)
            if f == 0.0:
                return a
            if f == 1.0:
                return b
            if not is_ref(a) and not is_ref(b):
                if kind == "F":
                    return (1 - f) * float(a) + f * float(b)
                return _vec3((1 - f) * np.asarray(a, float) + f * np.asarray(b, float))
        if kind == "F":
            return self.ref("MIX", {"Factor": f, "A": a, "B": b}, "Result",
                            {"data_type": "FLOAT", "blend_type": "MIX", "clamp_factor": True,
                             "clamp_result": False, "factor_mode": "UNIFORM"})
        return self.ref("MIX", {"Factor": f, "A": _jsonable(a), "B": _jsonable(b)}, "Result",
                        {"data_type": "RGBA" if kind == "C" else "VECTOR", "blend_type": "MIX",
                         "clamp_factor": True, "clamp_result": False, "factor_mode": "UNIFORM"})

    def add(self, a, b, kind: str):
        if not is_ref(a) and not is_ref(b):
            if kind == "F":
                return float(a) + float(b)
            return _vec3(np.asarray(a, float) + np.asarray(b, float))
        zero = 0.0 if kind == "F" else (0.0, 0.0, 0.0)
        if a == zero:
            return b
        if b == zero:
            return a
        if kind == "F":
            return self.ref("MATH", {"Value": a, "Value_001": b, "Value_002": 0.0}, "Value",
                            {"operation": "ADD", "use_clamp": False})
        return self.ref("VECT_MATH", {"Vector": _jsonable(a), "Vector_001": _jsonable(b),
                                      "Vector_002": [0.0] * 3, "Scale": 1.0}, "Vector",
                        {"operation": "ADD"})

    def normalize(self, v):
        return self.ref("VECT_MATH", {"Vector": v, "Vector_001": [0.0] * 3, "Vector_002": [0.0] * 3,
                                      "Scale": 1.0}, "Vector", {"operation": "NORMALIZE"})

    def mix_normals(self, t, a, b):
        if a is None or b is None or a == b:
            return a if b is None else b if a is None else a
        if not is_ref(t) and float(t) <= 0.0:
            return a
        if not is_ref(t) and float(t) >= 1.0:
            return b
        return self.normalize(self.mix(t, a, b, "V"))

    def mix_closures(self, f, a: Closure, b: Closure) -> Closure:
        if not is_ref(f):
            f = min(max(float(f), 0.0), 1.0)
        alpha = self.mix(f, a.alpha, b.alpha, "F")
        # weight of B among the opaque part: t = f·αB / α
        if not is_ref(a.alpha) and not is_ref(b.alpha) and a.alpha == b.alpha and a.alpha > 0:
            t = f
        elif not is_ref(b.alpha) and b.alpha == 0.0:
            t = 0.0
        elif not is_ref(a.alpha) and a.alpha == 0.0:
            t = 1.0
        else:
            t = self.ref("MATH", {"Value": self.mul(f, b.alpha), "Value_001": alpha, "Value_002": 0.0},
                         "Value", {"operation": "DIVIDE", "use_clamp": True})
        out = Closure(alpha=alpha, has_bsdf=a.has_bsdf or b.has_bsdf)
        out.base_color = self.mix(t, a.base_color, b.base_color, "C")
        out.emission = self.mix(t, a.emission, b.emission, "C")
        if a.has_bsdf and b.has_bsdf:
            for p in BSDF_PARAMS:
                setattr(out, p, self.mix(t, getattr(a, p), getattr(b, p), "F"))
            out.normal = self.mix_normals(t, a.normal, b.normal)
            out.ior = self.mix_ior(t, a, b)
        else:
            self._copy_bsdf(out, a if a.has_bsdf or not b.has_bsdf else b)
        return out

    @staticmethod
    def _copy_bsdf(out: Closure, src: Closure) -> None:
        for p in BSDF_PARAMS + ("normal", "ior"):
            setattr(out, p, getattr(src, p))

    def mix_ior(self, t, a: Closure, b: Closure):
        """The blended closure's IOR: the transmitting side's when only one side transmits
        (a constant transmission 0), else blended with ``t`` like the other parameters."""
        a_opaque = not is_ref(a.transmission) and a.transmission == 0.0
        b_opaque = not is_ref(b.transmission) and b.transmission == 0.0
        if a_opaque and not b_opaque:
            return b.ior
        if b_opaque and not a_opaque:
            return a.ior
        if a_opaque and b_opaque:
            return a.ior if a.ior == b.ior else DEFAULT_IOR
        return self.mix(t, a.ior, b.ior, "F")

    def add_closures(self, a: Closure, b: Closure) -> Closure:
        out = Closure(has_bsdf=a.has_bsdf or b.has_bsdf)
        out.base_color = self.add(a.base_color, b.base_color, "C")
        out.emission = self.add(a.emission, b.emission, "C")
        s = self.add(a.alpha, b.alpha, "F")
        if is_ref(s):
            out.alpha = self.ref("MATH", {"Value": s, "Value_001": 1.0, "Value_002": 0.0}, "Value",
                                 {"operation": "SUBTRACT", "use_clamp": True})
        else:
            out.alpha = min(max(s - 1.0, 0.0), 1.0)
        if a.has_bsdf and b.has_bsdf:
            for p in BSDF_PARAMS:
                setattr(out, p, self.mix(0.5, getattr(a, p), getattr(b, p), "F"))
            out.normal = self.mix_normals(0.5, a.normal, b.normal)
            out.ior = self.mix_ior(0.5, a, b)
        else:
            self._copy_bsdf(out, a if a.has_bsdf or not b.has_bsdf else b)
        return out

    # ------------------------------------------------------------------ estimates
    def estimate(self, v, fallback):
        """A constant stand-in for a ref (image means through simple arithmetic)."""
        if not is_ref(v):
            return v
        node = self.nodes[v["node"]]
        est = self._estimates.get(v["node"], {})
        if v["socket"] in est:
            return est[v["socket"]]
        t, ins, params = node["type"], node["inputs"], node["params"]
        try:
            if t == "VECT_MATH" and params.get("operation") == "SCALE":
                vec = np.asarray(self.estimate(_unjson(ins["Vector"]), fallback), float)
                return _vec3(vec * float(self.estimate(_unjson(ins["Scale"]), 1.0)))
            if t == "MATH" and params.get("operation") == "MULTIPLY":
                return float(self.estimate(_unjson(ins["Value"]), 1.0)) * float(
                    self.estimate(_unjson(ins["Value_001"]), 1.0))
            if t == "MIX" and params.get("blend_type") == "MIX":
                f = float(np.mean(self.estimate(_unjson(ins["Factor"]), 0.5)))
                a = np.asarray(self.estimate(_unjson(ins["A"]), fallback), float)
                b = np.asarray(self.estimate(_unjson(ins["B"]), fallback), float)
                r = (1 - f) * a + f * b
                return float(r) if r.ndim == 0 else _vec3(r)
        except (KeyError, TypeError, ValueError):
            pass
        return fallback


def _unjson(v):
    return tuple(v) if isinstance(v, list) else v


def _jsonable(v):
    if isinstance(v, tuple):
        return [float(x) for x in v]
    if isinstance(v, (np.floating, np.integer)):
        return float(v)
    return v


def _const_kind(v) -> str:
    return "F" if np.ndim(v) == 0 else "C"


def _convert_const(v, kind: str, want: str):
    if want == "S":
        return v
    if want == "F":
        if np.ndim(v) == 0:
            return float(v)
        if kind == "C":
            return float(sum(w * c for w, c in zip(LUMA, v)))
        return float(np.mean(v[:3]))
    if np.ndim(v) == 0:
        return (float(v),) * 3
    return _vec3(v[:3])


def _linked(socket) -> bool:
    return socket is not None and bool(socket.is_linked)


def _by_identifier(sockets, identifier):
    for s in sockets:
        if s.identifier == identifier:
            return s
    return None


def _group_output(tree):
    outs = [n for n in tree.nodes if n.type == "GROUP_OUTPUT"]
    for n in outs:
        if getattr(n, "is_active_output", False):
            return n
    return outs[0] if outs else None


def output_node(node_tree):
    """The active output node Cycles would use (``get_output_node`` exists on 3.x and 5.x)."""
    return node_tree.get_output_node("CYCLES") or node_tree.get_output_node("ALL")


def _clip01(v):
    return float(min(max(float(v), 0.0), 1.0))


@dataclass
class ObjectSpace:
    """What per-object nodes need (Texture Coordinate Object/Generated/Normal, object-space
    Normal Map): the object's matrix in description coordinates, its texture space, and the
    description's origin (for a Texture Coordinate naming another object)."""

    world_from_object: np.ndarray
    texspace_location: tuple = (0.0, 0.0, 0.0)
    texspace_size: tuple = (1.0, 1.0, 1.0)
    origin: tuple = (0.0, 0.0, 0.0)

    def __post_init__(self):
        self.world_from_object = np.asarray(self.world_from_object, np.float64)
        self.texspace_location = np.asarray(self.texspace_location, np.float64)
        self.texspace_size = np.asarray(self.texspace_size, np.float64)

    def matrix_of(self, obj) -> np.ndarray:
        m = np.array(obj.matrix_world, np.float64)
        m[:3, 3] -= np.asarray(self.origin, np.float64)
        return m

    def key(self) -> tuple:
        return (tuple(np.round(self.world_from_object, 9).ravel()),
                tuple(np.round(self.texspace_location, 9)), tuple(np.round(self.texspace_size, 9)))


def compile_material(mat, textures=None, space: ObjectSpace | None = None) -> Compiled:
    """Compile ``mat``'s node tree (it must use nodes). ``textures``: a texture collector
    (``index_of(image, material_name) → (row, info)``) or None to skip images. ``space``:
    the object the row is for, when :attr:`Compiled.needs_object_matrix` said it matters."""
    comp = _Compiler(mat.name, textures, space)
    out = output_node(mat.node_tree)
    if out is None:
        comp.note("no material output node")
        return Compiled(_row_constants(Closure(base_color=(0.0, 0.0, 0.0))), "", comp.notes)
    disp = out.inputs.get("Displacement")
    if _linked(disp):
        comp.note("displacement output ignored")
    surface = out.inputs.get("Surface")
    closure = comp.shader(surface, ())
    names = ("base_color", "roughness", "metallic", "specular", "emission", "alpha")
    # transmission/ior: program outputs only when the material transmits somewhere (the row
    # constants, transmission 0, say the rest; programs of opaque materials stay as before)
    if is_ref(closure.transmission) or closure.transmission != 0.0:
        names += ("transmission", "ior")
    # translucency: likewise only when something is translucent
    if is_ref(closure.translucency) or closure.translucency != 0.0:
        names += ("translucency",)
    refs = any(is_ref(getattr(closure, n)) for n in names)
    needs_program = refs or closure.normal is not None or (
        not is_ref(closure.alpha) and closure.alpha != 1.0)
    constants = _row_constants(closure, comp)
    program = ""
    if needs_program:
        outputs = {n: _jsonable(getattr(closure, n)) for n in names}
        outputs["normal"] = _jsonable(closure.normal)
        data = {"version": VERSION, "nodes": comp.nodes, "outputs": outputs}
        if closure.normal is not None:
            data["bump_shadowing"] = compat.BUMP_SHADOWING
        program = json.dumps(data, separators=(",", ":"))
    else:
        comp.uses_uvs = comp.uses_tangents = False
        comp.uv_maps = set()
    return Compiled(constants, program, comp.notes, comp.uses_uvs, comp.uses_tangents, comp.uv_maps,
                    bool(program) and comp.needs_object_matrix)


def _row_constants(c: Closure, comp: _Compiler | None = None) -> dict:
    est = (lambda v, fb: comp.estimate(v, fb)) if comp is not None else (lambda v, fb: v)  # noqa: E731
    base = est(c.base_color, GREY)
    rough = est(c.roughness, 0.5)
    metal = est(c.metallic, 0.0)
    spec = est(c.specular, 0.5)
    emit = est(c.emission, (0.0, 0.0, 0.0))
    trans = est(c.transmission, 0.0)
    ior = est(c.ior, DEFAULT_IOR)
    translucency = est(c.translucency, 0.0)

    def vec(v):
        return np.asarray(v, float).reshape(-1)[:3] if np.ndim(v) else np.full(3, float(v))

    def num(v):
        return float(v if np.ndim(v) == 0 else np.mean(v))

    return dict(
        base_color=tuple(float(x) for x in np.clip(vec(base), 0.0, 1.0)),
        roughness=_clip01(num(rough)),
        metallic=_clip01(num(metal)),
        specular=max(num(spec), 0.0),
        emission=tuple(float(x) for x in np.maximum(vec(emit), 0.0)),
        transmission=_clip01(num(trans)),
        ior=float(min(max(num(ior), IOR_RANGE[0]), IOR_RANGE[1])),
        translucency=_clip01(num(translucency)),
    )


def program_nodes(program: str) -> list:
    """The node list of a program string (tests, messages)."""
    return json.loads(program)["nodes"] if program else []


__all__ = ["Compiled", "compile_material", "output_node", "program_nodes"]
