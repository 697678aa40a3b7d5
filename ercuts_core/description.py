"""The scene description: the one interface between Blender (or any caller) and the core.

Everything the core needs is a frozen dataclass of C-contiguous numpy arrays in world
space, with fixed dtypes. The add-on builds it from Blender's depsgraph; tests and the
command line build or load it directly. It round-trips through one ``.npz`` file
(:func:`save_npz` / :func:`load_npz`) for bug reports and golden tests.

Conventions and units (documented once, here):

* Lengths in metres (Blender units after the unit scale), right-handed world frame.
* Colours are linear Rec.709 RGB.
* Emitter radiance (materials' ``emission``, area lights, world) in W·sr⁻¹·m⁻².
* Point/spot intensity in W/sr; sun irradiance in W/m² on a surface facing the sun.
* The camera looks down its local −Z axis with +Y up (Blender's convention);
  ``world_from_camera`` is a rigid transform (rotation + translation, no scale).
* Triangles wind counter-clockwise around their geometric normal (Blender's face
  normals); negative-scale objects must already have their winding flipped.
"""
from __future__ import annotations

import dataclasses
import os
from dataclasses import dataclass, field, fields

import numpy as np
from numpy.typing import NDArray

from .atomic import atomic_path
from .shading.textures import TextureTable

F32 = NDArray[np.float32]
F64 = NDArray[np.float64]
I32 = NDArray[np.int32]

SCHEMA_VERSION = 1

#: Area-light shapes (``AreaLights.shape``): Blender's SQUARE/RECTANGLE map to RECT,
#: DISK/ELLIPSE map to ELLIPSE.
SHAPE_RECT = 0
SHAPE_ELLIPSE = 1


def _f32(a, shape_tail: tuple[int, ...]) -> F32:
    """Return ``a`` as a C-contiguous float32 array of shape (N, *shape_tail)."""
    arr = np.ascontiguousarray(np.asarray(a, dtype=np.float32))
    if arr.size == 0:
        arr = arr.reshape((0, *shape_tail))
    return arr


def _i32(a) -> I32:
    arr = np.ascontiguousarray(np.asarray(a, dtype=np.int32))
    return arr


@dataclass(frozen=True)
class MeshTable:
    """All triangles of the scene, merged into one world-space mesh.

    Attributes:
        positions: (V, 3) float32 vertex positions, world space [m].
        triangles: (T, 3) int32 vertex indices, counter-clockwise around the face normal.
        material_ids: (T,) int32 row in :class:`MaterialTable`.
        object_ids: (T,) int32 index into ``SceneDescription.object_names``.
        normals: (V, 3) float32 unit shading normals, or None (all faces flat).
        smooth: (T,) bool, True where the face uses interpolated ``normals``;
            None means "smooth wherever normals are given".
        uvs: (T, 3, 2) float32 per-corner UV of the active render UV map, or None
            (no UV map: every hit reads UV (0, 0), as Cycles does).
        tangents: (T, 3, 4) float32 per-corner world-space MikkTSpace tangent xyz and
            bitangent sign w (Blender's ``calc_tangents``), or None (normal maps then
            use a tangent frame built from the shading normal, see ``shading.geometry``).
    """

    positions: F32
    triangles: I32
    material_ids: I32
    object_ids: I32
    normals: F32 | None = None
    smooth: NDArray[np.bool_] | None = None
    uvs: F32 | None = None
    tangents: F32 | None = None

    def __post_init__(self):
        object.__setattr__(self, "positions", _f32(self.positions, (3,)))
        tris = _i32(self.triangles)
        object.__setattr__(self, "triangles", tris.reshape(-1, 3) if tris.size == 0 else tris)
        object.__setattr__(self, "material_ids", _i32(self.material_ids).reshape(-1))
        object.__setattr__(self, "object_ids", _i32(self.object_ids).reshape(-1))
        if self.normals is not None:
            object.__setattr__(self, "normals", _f32(self.normals, (3,)))
        if self.smooth is not None:
            object.__setattr__(self, "smooth", np.ascontiguousarray(self.smooth, dtype=bool).reshape(-1))
        if self.uvs is not None:
            object.__setattr__(self, "uvs", _f32(self.uvs, (3, 2)))
        if self.tangents is not None:
            object.__setattr__(self, "tangents", _f32(self.tangents, (3, 4)))

    @property
    def n_triangles(self) -> int:
        return int(self.triangles.shape[0])


@dataclass(frozen=True)
class MaterialTable:
    """One row per material (structure of arrays).

    The BSDF is a Lambertian base plus an optional GGX specular lobe, a glass lobe and a
    diffuse transmission lobe (see :mod:`ercuts_core.bsdf`).

    Attributes:
        names: material names, for messages.
        base_color: (M, 3) float32 linear RGB albedo in [0, 1].
        roughness: (M,) float32 Principled roughness in [0, 1] (GGX alpha = roughness²).
        metallic: (M,) float32 in [0, 1].
        specular: (M,) float32 Principled "Specular (IOR Level)"; 0.5 ↔ F0 = 0.04; 0 = pure Lambert.
        emission: (M, 3) float32 emitted radiance [W·sr⁻¹·m⁻²] (colour × strength), two-sided.
        programs: per row, a shading program as JSON (format: :mod:`ercuts_core.shading`),
            or "" for the row's constants only. Default (``()``): "" for every row.
        transmission: (M,) float32 Principled transmission weight in [0, 1] (1: glass).
            Default (``()``): 0 for every row.
        ior: (M,) float32 index of refraction of the glass lobe. Default (``()``): 1.5.
        translucency: (M,) float32 weight in [0, 1] of the diffuse transmission lobe (Cycles'
            Translucent BSDF, tinted by ``base_color``; 1: a Translucent BSDF). Default
            (``()``): 0 for every row.
    """

    names: tuple[str, ...]
    base_color: F32
    roughness: F32
    metallic: F32
    specular: F32
    emission: F32
    programs: tuple[str, ...] = ()
    transmission: F32 | tuple = ()
    ior: F32 | tuple = ()
    translucency: F32 | tuple = ()

    def __post_init__(self):
        object.__setattr__(self, "names", tuple(str(n) for n in self.names))
        programs = tuple(str(p) for p in self.programs)
        object.__setattr__(self, "programs", programs if programs else ("",) * len(self.names))
        object.__setattr__(self, "base_color", _f32(self.base_color, (3,)))
        object.__setattr__(self, "emission", _f32(self.emission, (3,)))
        m = len(self.names)
        for name, default in (("transmission", 0.0), ("ior", 1.5), ("translucency", 0.0)):
            if len(np.asarray(getattr(self, name)).reshape(-1)) == 0:
                object.__setattr__(self, name, np.full(m, default, np.float32))
        for name in ("roughness", "metallic", "specular", "transmission", "ior", "translucency"):
            object.__setattr__(self, name, _f32(getattr(self, name), ()).reshape(-1))

    @property
    def n_materials(self) -> int:
        return len(self.names)

    @property
    def has_programs(self) -> bool:
        """True when any row has a shading program (else every row is constant)."""
        return any(self.programs)

    @staticmethod
    def diffuse(names, base_color, emission=None, programs=()) -> "MaterialTable":
        """Pure Lambertian materials (specular 0, metallic 0, roughness 1)."""
        base = np.asarray(base_color, np.float32).reshape(-1, 3)
        m = base.shape[0]
        em = np.zeros((m, 3), np.float32) if emission is None else np.asarray(emission, np.float32)
        return MaterialTable(tuple(names), base, np.ones(m), np.zeros(m), np.zeros(m), em,
                             tuple(programs))


@dataclass(frozen=True)
class PointLights:
    """Point and spot lights (a point light is a spot with ``cos_half_angle`` = −1).

    Attributes:
        position: (P, 3) float32 [m].
        intensity: (P, 3) float32 radiant intensity [W/sr] (Blender: colour·power/(4π)).
        direction: (P, 3) float32 unit spot axis (the direction the spot points).
        cos_half_angle: (P,) float32 cosine of half the spot's full cone angle; −1 for point lights.
        blend: (P,) float32 Blender spot_blend in [0, 1] (smoothstep falloff width).
        radius: (P,) float32 Blender's ``shadow_soft_size`` [m]; 0 = a point (sharp shadows).
            A light of radius r > 0 has radiance I/(π·r²) over its disk or sphere
            (:mod:`ercuts_core.sphere_lights`).
        object_ids: (P,) int32 index into ``object_names``.
        sphere: (P,) bool, how a light of radius > 0 is shaped (Cycles' ``is_sphere``): True =
            a sphere (Blender ≥ 4.0 with *Soft Falloff* off); False = a disk facing each
            receiver (*Soft Falloff* on, Blender's default, and every Blender 3.x).
            None (default): False for every light.
    """

    position: F32
    intensity: F32
    direction: F32
    cos_half_angle: F32
    blend: F32
    radius: F32
    object_ids: I32
    sphere: NDArray[np.bool_] | None = None

    def __post_init__(self):
        for name in ("position", "intensity", "direction"):
            object.__setattr__(self, name, _f32(getattr(self, name), (3,)))
        for name in ("cos_half_angle", "blend", "radius"):
            object.__setattr__(self, name, _f32(getattr(self, name), ()).reshape(-1))
        object.__setattr__(self, "object_ids", _i32(self.object_ids).reshape(-1))
        sphere = np.zeros(len(self.object_ids), bool) if self.sphere is None else self.sphere
        object.__setattr__(self, "sphere", np.ascontiguousarray(sphere, dtype=bool).reshape(-1))

    def __len__(self) -> int:
        return int(self.position.shape[0])


@dataclass(frozen=True)
class SunLights:
    """Distant (directional) lights.

    Attributes:
        direction: (S, 3) float32 unit direction the light travels (Blender: local −Z).
        irradiance: (S, 3) float32 irradiance on a surface facing the sun [W/m²].
        angle: (S,) float32 angular diameter [rad]: directions are uniform in the cone of
            half-angle angle/2 around the sun (Cycles ≥ 4.0); 0 = a delta direction.
        object_ids: (S,) int32.
    """

    direction: F32
    irradiance: F32
    angle: F32
    object_ids: I32

    def __post_init__(self):
        for name in ("direction", "irradiance"):
            object.__setattr__(self, name, _f32(getattr(self, name), (3,)))
        object.__setattr__(self, "angle", _f32(self.angle, ()).reshape(-1))
        object.__setattr__(self, "object_ids", _i32(self.object_ids).reshape(-1))

    def __len__(self) -> int:
        return int(self.direction.shape[0])


@dataclass(frozen=True)
class AreaLights:
    """One-sided planar area lights (rectangles and ellipses).

    A point on the light is ``center + a·axis_u + b·axis_v`` with (a, b) in [−1, 1]² for
    RECT and a² + b² ≤ 1 for ELLIPSE, so ``axis_u``/``axis_v`` are *half*-extent vectors
    (object scale applied). The light emits into the hemisphere of ``normal``
    (Blender: local −Z). Area lights are not intersectable: camera and BSDF rays pass
    through them, and they are reached by next-event estimation only.

    Attributes:
        center: (A, 3) float32 [m].
        axis_u: (A, 3) float32 half-extent along the light's local X [m].
        axis_v: (A, 3) float32 half-extent along the light's local Y [m].
        normal: (A, 3) float32 unit emission normal.
        radiance: (A, 3) float32 [W·sr⁻¹·m⁻²].
        shape: (A,) int32, SHAPE_RECT or SHAPE_ELLIPSE.
        object_ids: (A,) int32.
        spread: (A,) float32 Blender's ``spread`` [rad] in (0, π]: the full angle of the cone
            the light emits into (a soft-box grid, :mod:`ercuts_core.area_spread`); π (the
            default, also for None) is a plain Lambertian emitter.
    """

    center: F32
    axis_u: F32
    axis_v: F32
    normal: F32
    radiance: F32
    shape: I32
    object_ids: I32
    spread: F32 | None = None

    def __post_init__(self):
        for name in ("center", "axis_u", "axis_v", "normal", "radiance"):
            object.__setattr__(self, name, _f32(getattr(self, name), (3,)))
        object.__setattr__(self, "shape", _i32(self.shape).reshape(-1))
        object.__setattr__(self, "object_ids", _i32(self.object_ids).reshape(-1))
        spread = np.full(len(self.object_ids), np.pi) if self.spread is None else self.spread
        object.__setattr__(self, "spread", _f32(spread, ()).reshape(-1))

    def __len__(self) -> int:
        return int(self.center.shape[0])


def _empty_points() -> PointLights:
    return PointLights(np.zeros((0, 3)), np.zeros((0, 3)), np.zeros((0, 3)), [], [], [], [])


def _empty_suns() -> SunLights:
    return SunLights(np.zeros((0, 3)), np.zeros((0, 3)), [], [])


def _empty_areas() -> AreaLights:
    z = np.zeros((0, 3))
    return AreaLights(z, z, z, z, z, [], [])


@dataclass(frozen=True)
class CameraDesc:
    """Blender-style camera: the core derives the image window exactly as Blender does.

    Attributes:
        world_from_camera: (4, 4) float64 rigid transform; camera looks down −Z, +Y up.
        width, height: full-frame resolution in pixels (percentage already applied).
        projection: 'PERSP' or 'ORTHO'.
        lens: focal length [mm] (perspective).
        sensor_width, sensor_height: [mm].
        sensor_fit: 'AUTO', 'HORIZONTAL' or 'VERTICAL'.
        shift_x, shift_y: lens shift in units of the fitted image dimension.
        ortho_scale: width of the fitted dimension [m] (orthographic).
        pixel_aspect_x, pixel_aspect_y: Blender's pixel aspect.
        border: (xmin, ymin, xmax, ymax) fractions of the frame, y measured from the
            *bottom* (Blender's convention); used when ``use_border``.
        use_border: render only the border window.
        clip_start, clip_end: [m].
        aperture_radius: thin-lens aperture radius [m] (Cycles: lens·10⁻³/(2·f-stop) when
            depth of field is on); 0 = a pinhole (perspective only).
        focus_distance: depth of the plane in focus along the viewing axis [m] (Blender's
            focus distance, or the focus object's distance along the camera's −Z).
        aperture_blades: polygonal aperture with this many blades; 0 (or < 3) = a disk.
        aperture_rotation: rotation of the blades [rad].
        aperture_ratio: anamorphic ratio (the aperture's x extent is divided by it).
    """

    world_from_camera: F64
    width: int
    height: int
    projection: str = "PERSP"
    lens: float = 50.0
    sensor_width: float = 36.0
    sensor_height: float = 24.0
    sensor_fit: str = "AUTO"
    shift_x: float = 0.0
    shift_y: float = 0.0
    ortho_scale: float = 7.314
    pixel_aspect_x: float = 1.0
    pixel_aspect_y: float = 1.0
    border: tuple[float, float, float, float] = (0.0, 0.0, 1.0, 1.0)
    use_border: bool = False
    clip_start: float = 1e-3
    clip_end: float = 1e30
    aperture_radius: float = 0.0
    focus_distance: float = 10.0
    aperture_blades: int = 0
    aperture_rotation: float = 0.0
    aperture_ratio: float = 1.0

    def __post_init__(self):
        m = np.ascontiguousarray(np.asarray(self.world_from_camera, dtype=np.float64))
        object.__setattr__(self, "world_from_camera", m)
        object.__setattr__(self, "width", int(self.width))
        object.__setattr__(self, "height", int(self.height))
        object.__setattr__(self, "border", tuple(float(b) for b in self.border))
        object.__setattr__(self, "aperture_blades", int(self.aperture_blades))
        for name in ("aperture_radius", "focus_distance", "aperture_rotation", "aperture_ratio"):
            object.__setattr__(self, name, float(getattr(self, name)))


@dataclass(frozen=True)
class WorldMap:
    """An equirectangular environment texture (Blender's World → Environment Texture).

    Lookup, orientation and sampling follow Cycles: see :mod:`ercuts_core.envmap`.

    Attributes:
        radiance: (H, W, 3) float32 linear RGB radiance [W·sr⁻¹·m⁻²]: the image (linear,
            colour space already converted) × the Background strength. Row 0 is the *bottom*
            row (v = ½/H, toward −Z), as Blender stores ``Image.pixels``; column 0 is u = ½/W.
        rotation: (3, 3) float32 world → map-space rotation (d_map = rotation · d_world), from a
            Mapping node; identity by default.
    """

    radiance: F32
    rotation: F32 = field(default_factory=lambda: np.eye(3, dtype=np.float32))

    def __post_init__(self):
        # The shape is checked by validate.sanitize (a wrong one falls back to world_radiance).
        object.__setattr__(self, "radiance", np.ascontiguousarray(np.asarray(self.radiance, np.float32)))
        object.__setattr__(self, "rotation", _f32(self.rotation, ()).reshape(3, 3))


@dataclass(frozen=True)
class SceneDescription:
    """A complete scene: geometry, materials, lights, camera, world.

    ``camera`` may be None only so that validation can report "no camera" as an error.
    ``world_radiance`` is the constant background radiance (3,) [W·sr⁻¹·m⁻²].
    ``textures`` holds the images the materials' programs read (empty by default).
    """

    mesh: MeshTable
    materials: MaterialTable
    camera: CameraDesc | None
    point_lights: PointLights = field(default_factory=_empty_points)
    sun_lights: SunLights = field(default_factory=_empty_suns)
    area_lights: AreaLights = field(default_factory=_empty_areas)
    world_radiance: F32 = field(default_factory=lambda: np.zeros(3, np.float32))
    world_map: WorldMap | None = None        # an HDRI; when set it replaces world_radiance
    object_names: tuple[str, ...] = ()
    schema_version: int = SCHEMA_VERSION
    textures: TextureTable = field(default_factory=TextureTable)

    def __post_init__(self):
        object.__setattr__(self, "world_radiance", _f32(self.world_radiance, ()).reshape(3))
        object.__setattr__(self, "object_names", tuple(str(n) for n in self.object_names))

    def object_name(self, index: int) -> str:
        """Name of object ``index`` for messages (falls back to '#index')."""
        if 0 <= index < len(self.object_names):
            return self.object_names[index]
        return f"#{index}"

    def replace(self, **changes) -> "SceneDescription":
        return dataclasses.replace(self, **changes)


# --------------------------------------------------------------------------- npz I/O

_PARTS = {
    "mesh": MeshTable,
    "materials": MaterialTable,
    "point_lights": PointLights,
    "sun_lights": SunLights,
    "area_lights": AreaLights,
    "camera": CameraDesc,
    "world_map": WorldMap,
}


def _to_array(value):
    if isinstance(value, str):
        return np.array(value)
    if isinstance(value, tuple) and all(isinstance(v, str) for v in value):
        return np.array(value, dtype=str).reshape(len(value))
    return np.asarray(value)


def _from_array(cls, name: str, arr: np.ndarray):
    ftype = {f.name: f.type for f in fields(cls)}[name]
    if arr.dtype.kind == "U":
        return str(arr) if arr.ndim == 0 else tuple(str(s) for s in arr)
    if arr.ndim == 0:
        if "bool" in str(ftype):
            return bool(arr)
        if "int" in str(ftype) and "float" not in str(ftype):
            return int(arr)
        return float(arr) if arr.dtype.kind == "f" else arr.item()
    if "tuple" in str(ftype):
        return tuple(arr.tolist())
    return arr


def save_npz(desc: SceneDescription, path: str | os.PathLike) -> None:
    """Write ``desc`` to one ``.npz`` file, atomically (:mod:`ercuts_core.atomic`)."""
    data: dict[str, np.ndarray] = {
        "schema_version": np.array(desc.schema_version),
        "world_radiance": desc.world_radiance,
        "object_names": _to_array(desc.object_names),
    }
    for part in _PARTS:
        obj = getattr(desc, part)
        if obj is None:
            continue
        for f in fields(obj):
            value = getattr(obj, f.name)
            if value is not None:
                data[f"{part}.{f.name}"] = _to_array(value)
    data["textures.names"] = _to_array(desc.textures.names)
    data["textures.srgb"] = np.array(desc.textures.srgb, bool)
    for i, image in enumerate(desc.textures.images):
        data[f"textures.image.{i}"] = image
    with atomic_path(path, ".npz") as tmp:  # the suffix: numpy appends .npz to other names
        np.savez_compressed(tmp, **data)


def load_npz(path: str | os.PathLike) -> SceneDescription:
    """Read a description written by :func:`save_npz`."""
    with np.load(path, allow_pickle=False) as z:
        keys = set(z.files)
        parts = {}
        for part, cls in _PARTS.items():
            kwargs = {}
            for f in fields(cls):
                key = f"{part}.{f.name}"
                if key in keys:
                    kwargs[f.name] = _from_array(cls, f.name, z[key])
            if kwargs:
                parts[part] = cls(**kwargs)
        names = z["object_names"]
        tex_names = tuple(str(s) for s in z["textures.names"].reshape(-1)) if "textures.names" in keys else ()
        srgb = tuple(z["textures.srgb"].tolist()) if "textures.srgb" in keys else ()
        images = tuple(z[f"textures.image.{i}"] for i in range(len(tex_names)))
        textures = TextureTable(tex_names, images, srgb)
        return SceneDescription(
            mesh=parts["mesh"],
            materials=parts["materials"],
            camera=parts.get("camera"),
            point_lights=parts.get("point_lights", _empty_points()),
            sun_lights=parts.get("sun_lights", _empty_suns()),
            area_lights=parts.get("area_lights", _empty_areas()),
            world_radiance=z["world_radiance"],
            world_map=parts.get("world_map"),
            object_names=tuple(str(s) for s in names.reshape(-1)),
            schema_version=int(z["schema_version"]),
            textures=textures,
        )
