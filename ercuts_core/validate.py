"""The one place where bad input becomes an error, a warning with a fallback, or a silent skip.

Policy (shared docs, style-and-testing.md §2.6, after BlendLuxCore's rule):

* **error** — no meaningful image is possible: :class:`SceneError` with a message that
  names the Blender object where there is one (no camera, zero resolution, empty border);
* **warning** — the user can probably fix it: a fallback is used and one :class:`Issue`
  is reported per object (NaN/Inf vertices, indices out of range, bad material ids,
  non-finite light parameters, no lights at all → black image);
* **silent** — normal in Blender scenes: skipped and counted in ``stats`` only
  (zero-area triangles, zero-power lights, zero-size area lights).
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from .description import (AreaLights, CameraDesc, MaterialTable, MeshTable, PointLights, SceneDescription,
                          SunLights, WorldMap)
from .sampling import luminance
from .shading.program import compile_program
from .shading.textures import TextureTable, missing_image


class SceneError(ValueError):
    """The scene cannot be rendered; the message says why and names the object."""


@dataclass(frozen=True)
class Issue:
    """A problem found in the input.

    Attributes:
        severity: 'error', 'warning' or 'info'.
        code: stable identifier, e.g. 'nonfinite_vertices'.
        message: one line for the user, naming the object.
        object_name: the Blender object concerned, or ''.
    """

    severity: str
    code: str
    message: str
    object_name: str = ""

    def __str__(self) -> str:
        return self.message


@dataclass
class Validated:
    """A clean description plus what was found."""

    desc: SceneDescription
    issues: list[Issue]
    stats: dict[str, int]


def _names(desc: SceneDescription, object_ids: np.ndarray) -> list[str]:
    return [desc.object_name(int(i)) for i in np.unique(object_ids)]


def _per_object(desc: SceneDescription, object_ids: np.ndarray) -> list[tuple[str, int]]:
    ids, counts = np.unique(object_ids, return_counts=True)
    return [(desc.object_name(int(i)), int(c)) for i, c in zip(ids, counts)]


def _check_camera(desc: SceneDescription) -> None:
    cam = desc.camera
    if cam is None:
        raise SceneError("Scene has no active camera: set one in Scene properties")
    if cam.width < 1 or cam.height < 1:
        raise SceneError(f"Resolution {cam.width}x{cam.height} is empty: width and height must be >= 1")
    m = np.asarray(cam.world_from_camera)
    if m.shape != (4, 4) or not np.isfinite(m).all() or abs(np.linalg.det(m[:3, :3])) < 1e-12:
        raise SceneError("Camera transform is degenerate or not finite")
    if cam.projection not in ("PERSP", "ORTHO"):
        raise SceneError(f"Camera projection {cam.projection!r} is not supported (PERSP, ORTHO)")
    if cam.projection == "PERSP" and not cam.lens > 0:
        raise SceneError(f"Camera focal length {cam.lens} mm must be > 0")
    if cam.use_border:
        from .camera import render_window
        w = render_window(cam)
        if w.width < 1 or w.height < 1:
            raise SceneError(f"Render border {cam.border} is empty at {cam.width}x{cam.height}")


def _clean_mesh(desc: SceneDescription, issues: list[Issue], stats: dict[str, int]) -> MeshTable:
    mesh = desc.mesh
    pos, tris = mesh.positions, mesh.triangles
    nv = len(pos)
    keep = np.ones(len(tris), bool)
    # Indices out of range: drop the triangles, warn per object.
    bad_idx = ((tris < 0) | (tris >= nv)).any(axis=1) if len(tris) else keep[:0]
    if bad_idx.any():
        for name, n in _per_object(desc, mesh.object_ids[bad_idx]):
            issues.append(Issue("warning", "index_out_of_range",
                                f"Object '{name}': {n} triangle(s) with vertex indices out of range were skipped", name))
        keep &= ~bad_idx
    safe = np.where(bad_idx[:, None], 0, tris) if len(tris) else tris
    # With no vertices every triangle is out of range; one dummy vertex keeps `safe` indexable.
    padded = pos if nv else np.zeros((1, 3), np.float32)
    # NaN/Inf vertices: drop their triangles (Cycles does the same), warn per object.
    finite_v = np.isfinite(padded).all(axis=1)
    bad_pos = ~finite_v[safe].all(axis=1) & keep if len(tris) else keep[:0]
    if bad_pos.any():
        for name, n in _per_object(desc, mesh.object_ids[bad_pos]):
            issues.append(Issue("warning", "nonfinite_vertices",
                                f"Object '{name}': {n} triangle(s) with NaN/Inf vertices were skipped", name))
        keep &= ~bad_pos
    # Zero-area triangles: silent, counted.
    if len(tris):
        p = np.where(finite_v[:, None], padded, 0).astype(np.float64)[safe]
        area2 = np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1)
        degenerate = keep & ~(area2 > 0)
        stats["degenerate_triangles"] = int(degenerate.sum())
        keep &= ~degenerate
    # Material ids out of range: fall back to the last (grey) material, warn.
    mat_ids = mesh.material_ids.copy()
    bad_mat = (mat_ids < 0) | (mat_ids >= desc.materials.n_materials)
    if bad_mat.any():
        for name in _names(desc, mesh.object_ids[bad_mat & keep]):
            issues.append(Issue("warning", "material_out_of_range",
                                f"Object '{name}': material index out of range, using grey diffuse", name))
        mat_ids[bad_mat] = desc.materials.n_materials  # the fallback row appended below
    stats["triangles"] = int(keep.sum())
    normals = mesh.normals
    smooth = mesh.smooth
    if normals is not None and (len(normals) != nv or (smooth is not None and len(smooth) != len(tris))):
        issues.append(Issue("warning", "normal_count_mismatch",
                            f"{len(normals)} shading normals for {nv} vertices: normals ignored (flat shading)"))
        normals = smooth = None
    if normals is not None:
        ok = np.isfinite(normals).all(axis=1) & (np.linalg.norm(normals, axis=1) > 1e-12)
        normals = np.where(ok[:, None], normals, 0).astype(np.float32)
        normals = normals / np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-12)
        tri_ok = (ok if nv else np.zeros(1, bool))[safe].all(axis=1) if len(tris) else ok[:0]
        smooth = (np.ones(len(tris), bool) if smooth is None else smooth) & tri_ok
    uvs = _clean_corner_attribute(desc, mesh.uvs, "uvs", 2, issues)
    tangents = _clean_corner_attribute(desc, mesh.tangents, "tangents", 4, issues)
    return MeshTable(pos, tris[keep], mat_ids[keep], mesh.object_ids[keep],
                     normals, None if smooth is None else smooth[keep],
                     None if uvs is None else uvs[keep], None if tangents is None else tangents[keep])


def _clean_corner_attribute(desc: SceneDescription, values, name: str, width: int,
                            issues: list[Issue]):
    """Check a per-corner attribute ((T, 3, width) or None): wrong shape → warning and None
    (no UVs: UV (0, 0); no tangents: a frame from the normal); NaN/Inf → 0, warning per object."""
    if values is None:
        return None
    mesh = desc.mesh
    if values.shape != (mesh.n_triangles, 3, width):
        issues.append(Issue("warning", f"{name}_shape",
                            f"Mesh {name} have shape {values.shape}, "
                            f"expected ({mesh.n_triangles}, 3, {width}): "
                            f"{name} ignored"))
        return None
    bad = ~np.isfinite(values).all(axis=(1, 2))
    if bad.any():
        for obj, n in _per_object(desc, mesh.object_ids[bad]):
            issues.append(Issue("warning", f"nonfinite_{name}",
                                f"Object '{obj}': {n} triangle(s) with NaN/Inf {name}, replaced by 0", obj))
        values = np.where(np.isfinite(values), values, 0.0).astype(np.float32)
    return values


def _check_programs(mats: MaterialTable, programs: tuple[str, ...], n_textures: int,
                    issues: list[Issue]) -> tuple[str, ...]:
    """One warning per problem of a shading program (naming material and node); an unusable
    program is dropped (the material renders with its constants)."""
    if not any(programs):
        return programs
    out = list(programs)
    for row, (text, name) in enumerate(zip(programs, mats.names)):
        program, messages = compile_program(text, name, n_textures)
        for msg in messages:
            issues.append(Issue("warning", "shading_program", msg))
        if program is None:
            out[row] = ""
    return tuple(out)


def _clean_materials(mats: MaterialTable, issues: list[Issue], n_textures: int = 0) -> MaterialTable:
    """Clip to valid ranges, replace NaN with defaults, append the grey fallback row.

    Non-finite values are a warning per material (NaN → the default, an infinite emission
    → no emission: an infinitely bright emitter has no meaningful image)."""
    def fix(a, lo, hi, default):
        return np.clip(np.nan_to_num(a, nan=default, posinf=hi, neginf=lo), lo, hi)
    rows = [np.asarray(a, np.float64).reshape(mats.n_materials, -1) for a in
            (mats.base_color, mats.roughness, mats.metallic, mats.specular, mats.emission,
             mats.transmission, mats.ior, mats.translucency)]
    bad = ~np.isfinite(np.hstack(rows)).all(axis=1)
    for i in np.flatnonzero(bad):
        issues.append(Issue("warning", "nonfinite_material",
                            f"Material '{mats.names[i]}': NaN/Inf values replaced by defaults (no emission)"))
    # Translucency (a lobe weight) outside [0, 1]: clamped, with a warning naming the material
    tl = np.asarray(mats.translucency, np.float64)
    for i in np.flatnonzero(np.isfinite(tl) & ((tl < 0.0) | (tl > 1.0))):
        issues.append(Issue("warning", "translucency_out_of_range",
                            f"Material '{mats.names[i]}': translucency {tl[i]:g} outside [0, 1], "
                            f"clamped to {min(max(tl[i], 0.0), 1.0):g}"))
    programs = mats.programs
    if len(programs) != mats.n_materials:
        issues.append(Issue("warning", "program_count_mismatch",
                            f"{len(programs)} shading programs for {mats.n_materials} materials: "
                            "programs ignored (constant materials)"))
        programs = ("",) * mats.n_materials
    programs = _check_programs(mats, programs, n_textures, issues)
    return MaterialTable(
        mats.names + ("Ercuts fallback grey",),
        np.vstack([fix(mats.base_color, 0, 1, 0.8), [[0.8, 0.8, 0.8]]]),
        np.append(fix(mats.roughness, 0, 1, 0.5), 1.0),
        np.append(fix(mats.metallic, 0, 1, 0.0), 0.0),
        np.append(fix(mats.specular, 0, 1, 0.5), 0.0),
        np.vstack([np.where(np.isfinite(mats.emission), np.maximum(mats.emission, 0), 0),
                   [[0, 0, 0]]]).reshape(-1, 3),
        programs + ("",),
        np.append(fix(mats.transmission, 0, 1, 0.0), 0.0),
        np.append(fix(mats.ior, 1.0, 10.0, 1.5), 1.5),
        np.append(fix(mats.translucency, 0, 1, 0.0), 0.0),
    )


def _clean_image(name: str, image, issues: list[Issue]) -> np.ndarray:
    """One texture as (H, W, 4) float32: grey (H, W) and RGB (H, W, 3) images gain alpha 1;
    empty or malformed images become Cycles' magenta 1×1; NaN/Inf texels become 0."""
    im = np.asarray(image, np.float32)
    if im.ndim == 2:
        im = im[:, :, None]
    if im.ndim == 3 and im.shape[2] in (1, 3) and im.size:
        rgb = np.repeat(im, 3, axis=2) if im.shape[2] == 1 else im
        im = np.concatenate([rgb, np.ones(im.shape[:2] + (1,), np.float32)], axis=2)
    if im.ndim != 3 or im.shape[2] != 4 or im.size == 0:
        issues.append(Issue("warning", "empty_image",
                            f"Image '{name}' is empty or has shape {im.shape}: rendered magenta"))
        return missing_image()
    finite = np.isfinite(im)
    if not finite.all():
        issues.append(Issue("warning", "nonfinite_image",
                            f"Image '{name}': {int((~finite).sum())} NaN/Inf texel value(s) replaced by 0"))
        im = np.where(finite, im, 0.0).astype(np.float32)
    return np.ascontiguousarray(im)


def _clean_textures(textures: TextureTable, issues: list[Issue]) -> TextureTable:
    names = list(textures.names)[:len(textures.images)]
    names += [f"#{i}" for i in range(len(names), len(textures.images))]
    return TextureTable(tuple(names), tuple(_clean_image(n, im, issues)
                                            for n, im in zip(names, textures.images)), textures.srgb)


def _finite_rows(desc, arrays, object_ids, kind, issues) -> np.ndarray:
    ok = np.ones(len(object_ids), bool)
    for a in arrays:
        ok &= np.isfinite(a.reshape(len(object_ids), -1)).all(axis=1) if len(object_ids) else ok
    for name in _names(desc, object_ids[~ok]):
        issues.append(Issue("warning", "nonfinite_light",
                            f"Light '{name}': non-finite {kind} parameters, light skipped", name))
    return ok


#: Smallest area-light spread rendered [rad] (1°, Cycles 3.x's minimum; see _clean_spread).
MIN_SPREAD = np.radians(1.0)


def _clean_size(desc, values, object_ids, what: str, hi: float, issues: list[Issue]) -> np.ndarray:
    """A light size parameter (point radius, sun angle) with NaN/Inf or negative values set
    to 0 (a point / a delta direction), one warning per light; values above ``hi`` clipped."""
    v = np.asarray(values, np.float64)
    bad = ~(v >= 0) | ~np.isfinite(v)
    for name in _names(desc, object_ids[bad]):
        issues.append(Issue("warning", "bad_light_size",
                            f"Light '{name}': {what} is NaN, Inf or negative; rendered as 0 (sharp shadows)",
                            name))
    return np.clip(np.where(bad, 0.0, v), 0.0, hi)


def _clean_spread(desc, al: AreaLights, issues: list[Issue]) -> np.ndarray:
    """Area-light spread in [1°, π]: NaN/negative → π (no spread), below 1° → 1° (Cycles 3.x
    clamps there; Cycles ≥ 4.0 renders 0° as a collimated beam, which the core has no delta
    for), one warning per light."""
    v = np.asarray(al.spread, np.float64)
    bad = ~np.isfinite(v) | (v < 0)
    small = ~bad & (v < MIN_SPREAD)
    for name in _names(desc, al.object_ids[bad]):
        issues.append(Issue("warning", "bad_light_spread",
                            f"Light '{name}': spread is NaN, Inf or negative; rendered as 180°", name))
    for name in _names(desc, al.object_ids[small]):
        issues.append(Issue("warning", "small_light_spread",
                            f"Light '{name}': spread below 1° rendered as 1°", name))
    return np.clip(np.where(bad, np.pi, v), MIN_SPREAD, np.pi)


def _clean_lights(desc, issues, stats):
    pl, sl, al = desc.point_lights, desc.sun_lights, desc.area_lights
    ok = _finite_rows(desc, [pl.position, pl.intensity, pl.direction, pl.cos_half_angle, pl.blend],
                      pl.object_ids, "point/spot", issues)
    # A spot with a zero cone (cos of the half-angle ≥ 1) emits nothing, like zero intensity.
    on = ok & (luminance(np.maximum(pl.intensity, 0)) > 0) & (pl.cos_half_angle < 1.0)
    stats["dropped_zero_lights"] = int((ok & ~on).sum())
    radius = _clean_size(desc, pl.radius[on], pl.object_ids[on], "radius", np.inf, issues)
    pl = PointLights(pl.position[on], np.maximum(pl.intensity[on], 0), pl.direction[on],
                     pl.cos_half_angle[on], np.clip(pl.blend[on], 0, 1), radius, pl.object_ids[on],
                     pl.sphere[on])
    ok = _finite_rows(desc, [sl.direction, sl.irradiance], sl.object_ids, "sun", issues)
    on = ok & (luminance(np.maximum(sl.irradiance, 0)) > 0) & (np.linalg.norm(sl.direction, axis=1) > 0)
    stats["dropped_zero_lights"] += int((ok & ~on).sum())
    d = sl.direction[on] / np.linalg.norm(sl.direction[on], axis=1, keepdims=True)
    angle = _clean_size(desc, sl.angle[on], sl.object_ids[on], "angle", np.pi, issues)
    sl = SunLights(d, np.maximum(sl.irradiance[on], 0), angle, sl.object_ids[on])
    ok = _finite_rows(desc, [al.center, al.axis_u, al.axis_v, al.normal, al.radiance],
                      al.object_ids, "area", issues)
    with np.errstate(over="ignore", invalid="ignore"):    # non-finite rows are dropped by `ok`
        area = np.linalg.norm(np.cross(al.axis_u.astype(np.float64), al.axis_v.astype(np.float64)), axis=1)
    on = ok & (luminance(np.maximum(al.radiance, 0)) > 0) & (area > 0) & (np.linalg.norm(al.normal, axis=1) > 0)
    stats["dropped_zero_lights"] += int((ok & ~on).sum())
    n = al.normal[on] / np.linalg.norm(al.normal[on], axis=1, keepdims=True)
    spread = _clean_spread(desc, al, issues)[on]
    al = AreaLights(al.center[on], al.axis_u[on], al.axis_v[on], n, np.maximum(al.radiance[on], 0),
                    al.shape[on], al.object_ids[on], spread)
    return pl, sl, al


def _clean_lens(cam: CameraDesc, issues: list[Issue]) -> CameraDesc:
    """The camera's thin-lens parameters: NaN/Inf or negative aperture → a pinhole, a bad focus
    distance → a pinhole, a bad ratio → 1, negative blades → a disk, one warning each; depth
    of field on an orthographic camera is not supported (pinhole, warning); the focus distance
    is at least 10⁻⁵ m (as Cycles)."""
    r, f, ratio = cam.aperture_radius, cam.focus_distance, cam.aperture_ratio
    fixes = {}
    if not (np.isfinite(r) and r >= 0):
        issues.append(Issue("warning", "bad_aperture", "Camera: aperture is NaN, Inf or negative; "
                                                       "depth of field off"))
        r = 0.0
    if r > 0 and not (np.isfinite(f) and f >= 0):
        issues.append(Issue("warning", "bad_focus", "Camera: focus distance is NaN, Inf or negative; "
                                                    "depth of field off"))
        r = 0.0
    if r > 0 and cam.projection == "ORTHO":
        issues.append(Issue("warning", "ortho_dof", "Camera: depth of field of orthographic cameras "
                                                    "is not supported; rendered sharp"))
        r = 0.0
    if not (np.isfinite(ratio) and ratio > 0):
        issues.append(Issue("warning", "bad_aperture_ratio", "Camera: aperture ratio is NaN, Inf or "
                                                             "not positive; using 1"))
        fixes["aperture_ratio"] = 1.0
    if not np.isfinite(cam.aperture_rotation):
        fixes["aperture_rotation"] = 0.0
    if cam.aperture_blades < 3:
        fixes["aperture_blades"] = 0
    fixes["aperture_radius"] = r
    if r > 0:
        fixes["focus_distance"] = max(f, 1e-5)
    return dataclasses.replace(cam, **fixes)


def _clean_world_map(desc: SceneDescription, issues: list[Issue]) -> WorldMap | None:
    """The environment map with NaN/Inf/negative texels set to 0 and an orthonormal rotation;
    None (the constant ``world_radiance`` is used) for a map without texels."""
    wm = desc.world_map
    if wm is None:
        return None
    rad = wm.radiance
    if rad.ndim != 3 or rad.shape[-1] != 3 or rad.shape[0] == 0 or rad.shape[1] == 0:
        issues.append(Issue("warning", "empty_world_map",
                            f"World: the environment image has no pixels (shape {rad.shape}); "
                            "using the constant world colour"))
        return None
    bad = ~np.isfinite(rad) | (rad < 0)
    if bad.any():
        issues.append(Issue("warning", "bad_world_map",
                            f"World: {int(bad.any(axis=2).sum())} environment texels are NaN, Inf or "
                            "negative; rendered black"))
        rad = np.where(bad, np.float32(0), rad)
    rot = wm.rotation.astype(np.float64)
    if not np.isfinite(rot).all():
        issues.append(Issue("warning", "bad_world_rotation", "World: non-finite mapping rotation; ignored"))
        rot = np.eye(3)
    elif not np.allclose(rot @ rot.T, np.eye(3), atol=1e-4) or np.linalg.det(rot) <= 0:
        issues.append(Issue("warning", "bad_world_rotation",
                            "World: the mapping is not a rotation; using its nearest rotation"))
        u, _, vt = np.linalg.svd(rot)
        rot = u @ vt
        if np.linalg.det(rot) <= 0:
            rot = np.eye(3)
    return WorldMap(rad, rot)


def has_emitters(desc: SceneDescription) -> bool:
    """True when anything in a (clean) description emits light."""
    emissive = luminance(desc.materials.emission) > 0
    if desc.materials.has_programs:     # an emission program may light a row with no constant
        for row, text in enumerate(desc.materials.programs):
            program = compile_program(text, "", len(desc.textures))[0]
            emissive[row] |= program is not None and program.has("emission")
    tri_emit = emissive[desc.mesh.material_ids].any() if desc.mesh.n_triangles else False
    return bool(len(desc.point_lights) or len(desc.sun_lights) or len(desc.area_lights) or tri_emit
                or luminance(desc.world_radiance) > 0
                or (desc.world_map is not None and bool((luminance(desc.world_map.radiance) > 0).any())))


def sanitize(desc: SceneDescription) -> Validated:
    """Check ``desc``; raise :class:`SceneError` for fatal problems, else return a clean copy.

    The clean copy has only finite, in-range triangles, a material table with a grey
    fallback row appended (used for out-of-range ids), and only lights that emit.
    """
    issues: list[Issue] = []
    stats: dict[str, int] = {}
    _check_camera(desc)
    mesh = _clean_mesh(desc, issues, stats)
    mats = _clean_materials(desc.materials, issues, len(desc.textures))
    pl, sl, al = _clean_lights(desc, issues, stats)
    desc = desc.replace(world_map=_clean_world_map(desc, issues))
    world = np.clip(np.nan_to_num(desc.world_radiance, nan=0.0, posinf=0.0), 0, None)
    if not np.isfinite(desc.world_radiance).all():
        issues.append(Issue("warning", "nonfinite_world", "World: NaN/Inf background colour, rendered black"))
    textures = _clean_textures(desc.textures, issues)
    clean = desc.replace(mesh=mesh, materials=mats, point_lights=pl, sun_lights=sl, area_lights=al,
                         world_radiance=world, textures=textures, camera=_clean_lens(desc.camera, issues))
    if not has_emitters(clean):
        issues.append(Issue("warning", "no_lights",
                            "Scene has no lights (or all lights have zero power): the image is black"))
    return Validated(clean, issues, stats)
