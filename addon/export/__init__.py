"""Evaluated depsgraph → ``ercuts_core.description.SceneDescription``.

:func:`export_scene` walks ``depsgraph.object_instances`` once: every visible
mesh-like object (modifiers, geometry nodes and instancing already applied by the
depsgraph) is read once per distinct evaluated mesh and placed once per instance
with a copy of its world matrix; lights go to :mod:`.lights`; materials are
collected on first use (:mod:`.materials`); the camera and world come from the scene.
Nothing here touches bpy outside the calling thread, and the result is plain numpy.
"""
from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass, field

import numpy as np

from .camera import CameraExportError, camera_desc, render_size
from .lights import LightCollector
from .images import TextureCollector
from .materials import MaterialCollector
from .mesh import GEOMETRY_TYPES, read_mesh, transform_mesh
from .visibility import ray_visibility_notes
from .world import world_background

__all__ = ["ExportCancelled", "ExportError", "ExportResult", "export_scene", "render_size"]


#: Grid [m] of the description's origin (see "near-camera coordinates" in export_scene).
ORIGIN_GRID = 1024.0


class ExportError(Exception):
    """The scene cannot be rendered; the message is meant for the user."""


class ExportCancelled(Exception):
    """``should_stop`` asked to abandon the export."""


@dataclass
class ExportResult:
    """What :func:`export_scene` produced.

    Attributes:
        description: the scene for the core.
        warnings: user-facing messages about things that were ignored or approximated.
        has_emitters: False when nothing emits light (no lights, emissive materials or world).
        seconds: time spent exporting.
        stats: counts, e.g. {'triangles': .., 'instances': .., 'meshes': ..}.
    """

    description: object
    warnings: list[str] = field(default_factory=list)
    has_emitters: bool = True
    seconds: float = 0.0
    stats: dict = field(default_factory=dict)


def _instance_name(inst) -> str:
    name = inst.object.name
    if inst.is_instance and inst.parent is not None:
        return f"{inst.parent.name}/{name}"
    return name


def _relative(matrix_world, origin: np.ndarray) -> np.ndarray:
    """A copy of ``matrix_world`` (4×4 float64) translated by −``origin``."""
    m = np.array(matrix_world, np.float64)
    m[:3, 3] -= origin
    return m


def _mesh_key(ob):
    """Instances of the same evaluated geometry share one key (and one read)."""
    if ob.type == "MESH" and ob.data is not None:
        return ("ME", ob.data.as_pointer())
    return ("OB", ob.original.name_full, ob.data.as_pointer() if ob.data is not None else 0)


def _optional_fields(cls, **values) -> dict:
    """The given fields that ``cls`` defines and that are not None (fields added by issue 14:
    ``MeshTable.uvs/tangents``, ``SceneDescription.textures``)."""
    known = {f.name for f in dataclasses.fields(cls)}
    return {k: v for k, v in values.items() if v is not None and k in known}


def _note_visibility(ob, noted: set[str], warnings: list[str]) -> None:
    """Append ``ob``'s :func:`.visibility.ray_visibility_notes` to ``warnings`` once per object."""
    if ob.name not in noted:
        noted.add(ob.name)
        warnings += ray_visibility_notes(ob)


def export_scene(depsgraph, *, camera_override=None, size=None, use_border=None,
                 require_camera=True, should_stop=None, texture_cache=None) -> ExportResult:
    """Export the evaluated scene of ``depsgraph`` (its view layer) for the core.

    Args:
        camera_override: camera object to use instead of ``scene.camera``.
        size: full-frame (width, height) in pixels; default resolution × percentage.
        use_border: override ``render.use_border``.
        require_camera: raise :class:`ExportError` when there is no camera (else camera=None).
        should_stop: callable polled during the export; True raises :class:`ExportCancelled`.
        texture_cache: a dict kept between exports (the viewport's): unchanged images are
            not read again; it is replaced by this export's images.
    """
    from ercuts_core.description import MeshTable, SceneDescription

    t0 = time.monotonic()
    scene = depsgraph.scene
    view_layer = depsgraph.view_layer
    warnings: list[str] = []

    # ---------------------------------------------------------------- camera
    cam_obj = camera_override if camera_override is not None else scene.camera
    if cam_obj is not None:
        cam_obj = cam_obj.evaluated_get(depsgraph)
    camera = None
    if cam_obj is not None or require_camera:
        try:
            camera, cam_warnings = camera_desc(scene, cam_obj, size, use_border)
            warnings += cam_warnings
        except CameraExportError as exc:
            raise ExportError(str(exc)) from None

    # Near-camera coordinates: the description's origin moves to the multiple of
    # ORIGIN_GRID metres nearest the camera, so scenes far from Blender's origin keep
    # float32 precision where they are seen (1e5 m away the float32 spacing is 8 mm and
    # the tracer's offsets grow with |p|). A pure translation, so the image does not
    # change; scenes within 512 m of the origin are exported unshifted.
    origin = np.zeros(3)
    if camera is not None:
        origin = np.round(camera.world_from_camera[:3, 3] / ORIGIN_GRID) * ORIGIN_GRID
        shifted = camera.world_from_camera.copy()
        shifted[:3, 3] -= origin
        camera = dataclasses.replace(camera, world_from_camera=shifted)

    # ---------------------------------------------------------------- objects
    textures = TextureCollector(cache=texture_cache)
    materials = MaterialCollector(override=getattr(view_layer, "material_override", None),
                                  textures=textures)
    lights = LightCollector()
    names: list[str] = []
    local_cache: dict = {}
    parts = dict(positions=[], triangles=[], normals=[], smooth=[], material_ids=[], object_ids=[],
                 uvs=[], tangents=[])
    mesh_warnings: list[str] = []
    noted: set[str] = set()                  # objects whose ray-visibility note is given
    n_vertices = 0
    n_instances = 0
    skipped = dict(empty_meshes=0, degenerate_transforms=0)   # silent, counted (policy §2.6)
    for count, inst in enumerate(depsgraph.object_instances):
        if should_stop is not None and count % 1000 == 999 and should_stop():
            raise ExportCancelled()
        ob = inst.object
        if ob.original.hide_render:
            continue
        if ob.type == "LIGHT":
            _note_visibility(ob, noted, lights.warnings)
            names.append(_instance_name(inst))
            lights.add(ob.data, _relative(inst.matrix_world, origin), len(names) - 1, ob.name)
            continue
        if ob.type not in GEOMETRY_TYPES or not inst.show_self:
            continue
        _note_visibility(ob, noted, mesh_warnings)
        # UVs and tangents only for objects whose materials read them (they cost memory).
        slot_rows = materials.slot_table(ob, _relative(inst.matrix_world, origin), origin)
        used_rows = [materials.rows[r] for r in np.unique(slot_rows)]
        want_uvs = any(r.uses_uvs for r in used_rows)
        want_tangents = any(r.uses_tangents for r in used_rows)
        uv_maps = frozenset().union(*(r.uv_maps for r in used_rows))
        key = (_mesh_key(ob), want_uvs, want_tangents, uv_maps)
        local = local_cache.get(key)
        if local is None:
            mesh = ob.to_mesh()
            try:
                local = (read_mesh(mesh, want_uvs, want_tangents, uv_maps)
                         if mesh is not None else None)
            finally:
                ob.to_mesh_clear()
            local_cache[key] = local
            if local is not None and local.notes:
                mesh_warnings.append(f"Object '{ob.name}': " + "; ".join(local.notes))
        if local is None or local.n_triangles == 0:
            skipped["empty_meshes"] += 1
            continue
        placed = transform_mesh(local, _relative(inst.matrix_world, origin))  # copy now
        if placed is None:
            skipped["degenerate_transforms"] += 1
            continue
        names.append(_instance_name(inst))
        n_instances += 1
        parts["positions"].append(placed.positions)
        parts["normals"].append(placed.normals)
        parts["triangles"].append(placed.triangles + n_vertices)
        parts["smooth"].append(local.smooth)
        parts["material_ids"].append(slot_rows[np.clip(local.slots, 0, len(slot_rows) - 1)])
        parts["object_ids"].append(np.full(local.n_triangles, len(names) - 1, np.int32))
        parts["uvs"].append(placed.uvs)
        parts["tangents"].append(placed.tangents)
        n_vertices += len(placed.positions)

    # ---------------------------------------------------------------- assemble
    def cat(key, tail, dtype):
        chunks = parts[key]
        return np.concatenate(chunks).astype(dtype) if chunks else np.zeros((0, *tail), dtype)

    def per_corner(key, width):
        """Concatenate per-corner arrays; objects without them get zeros (UV 0 as Cycles)."""
        chunks = parts[key]
        if not any(c is not None for c in chunks):
            return None
        return np.concatenate([
            c if c is not None else np.zeros((len(t), 3, width), np.float32)
            for c, t in zip(chunks, parts["triangles"])]).astype(np.float32)

    smooth = cat("smooth", (), bool)
    any_smooth = bool(smooth.any())
    mesh_table = MeshTable(
        positions=cat("positions", (3,), np.float32),
        triangles=cat("triangles", (3,), np.int32),
        material_ids=cat("material_ids", (), np.int32),
        object_ids=cat("object_ids", (), np.int32),
        normals=cat("normals", (3,), np.float32) if any_smooth else None,
        smooth=smooth if any_smooth else None,
        **_optional_fields(MeshTable, uvs=per_corner("uvs", 2), tangents=per_corner("tangents", 4)),
    )
    material_table = materials.table()
    points, suns, areas = lights.tables()
    world = scene.world
    override = getattr(view_layer, "world_override", None)
    if override is not None:
        world = override
    radiance, world_map, world_warnings = world_background(world)

    texture_table = textures.table() if textures.names else None
    if texture_cache is not None:
        texture_cache.clear()
        texture_cache.update(textures.cache_out)
    warnings += materials.warnings + textures.warnings + mesh_warnings + lights.warnings + world_warnings
    if scene.render.use_motion_blur:
        warnings.append("motion blur ignored")

    used = np.unique(mesh_table.material_ids)
    emissive_mesh = bool(len(used) and (material_table.emission[used] > 0).any())
    has_emitters = bool(len(points) or len(suns) or len(areas) or emissive_mesh
                        or (radiance > 0).any())
    desc = SceneDescription(
        mesh=mesh_table, materials=material_table, camera=camera,
        point_lights=points, sun_lights=suns, area_lights=areas,
        world_radiance=radiance, object_names=tuple(names),
        **_optional_fields(SceneDescription, textures=texture_table),
    )
    if world_map is not None:                            # an HDRI replaces world_radiance
        desc = desc.replace(world_map=world_map)
    return ExportResult(
        description=desc, warnings=warnings, has_emitters=has_emitters,
        seconds=time.monotonic() - t0,
        stats=dict(triangles=mesh_table.n_triangles, instances=n_instances,
                   meshes=sum(v is not None for v in local_cache.values()),
                   lights=len(points) + len(suns) + len(areas), **skipped,
                   textures=len(textures.names), texture_bytes=textures.nbytes,
                   texture_reads=textures.reads,
                   origin=tuple(float(x) for x in origin)),
    )
