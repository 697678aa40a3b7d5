"""Blender materials → rows of the core's ``MaterialTable``.

Each material's node tree is compiled by :mod:`.shaders` into the row's constants plus a
shading program (``MaterialTable.programs``; "" when the constants say everything, so
scenes with constant materials export exactly as before issue 14). Images the programs
read go to the scene's texture table (:mod:`.images`). Everything that cannot be
translated gives *one* warning per material naming the nodes, and the documented fallback
(the input's own value for an unsupported value node, grey diffuse for an unsupported
shader). Glass and mirrors (Principled Transmission/IOR, Glass, Refraction, Glossy)
fill the table's ``transmission`` and ``ior`` columns, the Translucent BSDF its
``translucency`` column (mapping in :mod:`.shaders`).
Materials without a node tree render their viewport colour as a diffuse, like Cycles;
objects without a material get Cycles' default grey diffuse. Materials with an
object-space Normal Map get one row per object matrix.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np

from .. import compat
from .images import TextureCollector
from .shaders import ObjectSpace, compile_material
from .shaders import output_node as output_node  # noqa: F401  (re-exported for lights/world)

#: Cycles' default surface (objects without material, unsupported shaders): grey diffuse.
DEFAULT_GREY = (0.8, 0.8, 0.8)
DEFAULT_MATERIAL_NAME = "<default surface>"
#: Rows per material for per-object nodes (scattered instances would multiply rows); beyond
#: it, objects share the base row, whose coordinates are the core's world-space ones.
MAX_OBJECT_VARIANTS = 256


@dataclass
class MaterialRow:
    """One row of the MaterialTable (see ``ercuts_core.description.MaterialTable``)."""

    name: str
    base_color: tuple = DEFAULT_GREY
    roughness: float = 1.0
    metallic: float = 0.0
    specular: float = 0.0
    emission: tuple = (0.0, 0.0, 0.0)
    #: glass lobe weight (Principled Transmission Weight; 1 = Glass BSDF) and its IOR
    transmission: float = 0.0
    ior: float = 1.5
    #: weight of the translucent lobe (1 = Translucent BSDF)
    translucency: float = 0.0
    #: shading program (JSON, ``ercuts_core.shading``); "" = the constants above
    program: str = ""
    uses_uvs: bool = False
    uses_tangents: bool = False
    uv_maps: frozenset = frozenset()

    #: an object-space Normal Map: one row per object matrix (``MaterialCollector``)
    needs_object_matrix: bool = False

    @property
    def is_emissive(self) -> bool:
        return max(self.emission) > 0.0


@dataclass
class _Reader:
    """Reads one material's node tree and collects what it could not translate."""

    name: str
    notes: list = field(default_factory=list)

    def note(self, text: str) -> None:
        if text not in self.notes:
            self.notes.append(text)

    def value(self, socket, default=None):
        """Constant value of an input socket: its own value, or an RGB/Value node's."""
        if socket is None:
            return default
        node, out = follow_link(socket)
        if node is None:
            return _plain(socket.default_value)
        if node.bl_idname in {"ShaderNodeRGB", "ShaderNodeValue"}:
            return _plain(out.default_value)
        self.note(f"input '{socket.name}' linked to unsupported node '{node.name}' "
                  f"({node.bl_idname}), using the input's own value")
        return _plain(socket.default_value)

    def color(self, socket, default=DEFAULT_GREY) -> tuple:
        v = self.value(socket, default)
        return tuple(float(c) for c in v[:3])

    def scalar(self, socket, default=0.0) -> float:
        v = self.value(socket, default)
        return float(v if np.ndim(v) == 0 else np.mean(v[:3]))


def _plain(value):
    """bpy float arrays → tuples, floats stay floats."""
    try:
        return tuple(value)
    except TypeError:
        return float(value)


def follow_link(socket):
    """(node, output socket) feeding ``socket``, skipping reroutes; (None, None) if unlinked/muted."""
    seen = 0
    while socket is not None and socket.is_linked and seen < 64:
        seen += 1
        link = socket.links[0]
        if getattr(link, "is_muted", False) or not link.is_valid:
            return None, None
        node = link.from_node
        if node.bl_idname == "NodeReroute":
            socket = node.inputs[0]
            continue
        return node, link.from_socket
    return None, None


def _texspace(obj) -> tuple:
    """(location, size) of the object's texture space (Blender's Generated coordinates);
    the unit box when its data has none."""
    data = getattr(obj, "data", None)
    loc = getattr(data, "texspace_location", None)
    size = getattr(data, "texspace_size", None)
    if loc is None or size is None:
        return (0.0, 0.0, 0.0), (1.0, 1.0, 1.0)
    return tuple(loc), tuple(size)


def read_material(mat, textures=None) -> tuple[MaterialRow, list[str]]:
    """One material's row (with its shading program), and the list of things that could
    not be translated. ``textures``: the scene's :class:`.images.TextureCollector`."""
    if not compat.uses_nodes(mat):
        row = MaterialRow(mat.name, base_color=tuple(float(c) for c in mat.diffuse_color[:3]))
        return row, []
    compiled = compile_material(mat, textures)
    row = MaterialRow(mat.name, **compiled.constants, program=compiled.program,
                      uses_uvs=compiled.uses_uvs, uses_tangents=compiled.uses_tangents,
                      uv_maps=frozenset(compiled.uv_maps),
                      needs_object_matrix=compiled.needs_object_matrix)
    return row, compiled.notes


class MaterialCollector:
    """Builds the scene's material table: one row per distinct Blender material."""

    def __init__(self, override=None, textures: TextureCollector | None = None):
        self.override = override
        self.textures = textures if textures is not None else TextureCollector()
        self.rows: list[MaterialRow] = []
        self.warnings: list[str] = []
        self._index: dict = {}
        self._variants: dict[int, int] = {}

    def index_of(self, mat) -> int:
        """Row of ``mat`` (None → the default surface), exporting it on first use."""
        if self.override is not None:
            mat = self.override
        key = DEFAULT_MATERIAL_NAME if mat is None else "MA" + mat.original.name_full
        row = self._index.get(key)
        if row is not None:
            return row
        if mat is None:
            material = MaterialRow(DEFAULT_MATERIAL_NAME)
        else:
            material, notes = read_material(mat, self.textures)
            if notes:
                self.warnings.append(f"Material '{mat.name}': " + "; ".join(notes))
        self._index[key] = len(self.rows)
        self.rows.append(material)
        return self._index[key]

    def slot_table(self, obj, world_from_object=None, origin=(0.0, 0.0, 0.0)) -> np.ndarray:
        """int32 array mapping each material slot of ``obj`` to a row (at least one entry).

        Materials with per-object nodes (Texture Coordinate Object/Generated/Normal,
        object-space Normal Map) get one row per object matrix and texture space
        (``world_from_object``: 4×4 in description coordinates, ``origin``: the
        description's origin), compiled again with that :class:`.shaders.ObjectSpace`.
        """
        mats = [slot.material for slot in obj.material_slots] or [None]
        slots = [self.index_of(m) for m in mats]
        if world_from_object is not None:
            space = None
            for i, (m, r) in enumerate(zip(mats, slots)):
                if self.rows[r].needs_object_matrix:
                    space = space or ObjectSpace(world_from_object, *_texspace(obj), origin)
                    slots[i] = self._object_variant(r, self.override or m, space)
        return np.asarray(slots, np.int32)

    def _object_variant(self, row: int, mat, space: ObjectSpace) -> int:
        """The row of material ``mat`` (base row ``row``) compiled for one object."""
        key = ("OBJ", row, space.key())
        found = self._index.get(key)
        if found is not None:
            return found
        count = self._variants.get(row, 0)
        if count >= MAX_OBJECT_VARIANTS:
            if count == MAX_OBJECT_VARIANTS:
                self.warnings.append(
                    f"Material '{mat.name}': more than {MAX_OBJECT_VARIANTS} objects use its "
                    f"object-space nodes (Texture Coordinate Object/Generated/Normal, object-space "
                    f"Normal Map); the others use world-space coordinates")
                self._variants[row] = count + 1
            return row
        self._variants[row] = count + 1
        compiled = compile_material(mat, self.textures, space)  # notes: same as the base row's
        variant = dataclasses.replace(self.rows[row], **compiled.constants, program=compiled.program,
                                      needs_object_matrix=False)
        self._index[key] = len(self.rows)
        self.rows.append(variant)
        return self._index[key]

    def table(self):
        from ercuts_core.description import MaterialTable

        rows = self.rows or [MaterialRow(DEFAULT_MATERIAL_NAME)]
        return MaterialTable(
            names=tuple(r.name for r in rows),
            base_color=np.array([r.base_color for r in rows], np.float32).reshape(-1, 3),
            roughness=np.array([r.roughness for r in rows], np.float32),
            metallic=np.array([r.metallic for r in rows], np.float32),
            specular=np.array([r.specular for r in rows], np.float32),
            emission=np.array([r.emission for r in rows], np.float32).reshape(-1, 3),
            programs=tuple(r.program for r in rows),
            transmission=np.array([r.transmission for r in rows], np.float32),
            ior=np.array([r.ior for r in rows], np.float32),
            translucency=np.array([r.translucency for r in rows], np.float32),
        )
