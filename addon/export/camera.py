"""Blender camera + render settings → the core's ``CameraDesc``.

The core derives the image window exactly like Blender's ``Camera.view_frame()``
(sensor fit, shift, pixel aspect), so this module only copies parameters. The camera
matrix is handed over with its scale removed (rotation + translation).

Depth of field follows Cycles' ``blender/camera.cpp``: aperture radius = lens·10⁻³/(2·f-stop)
(f-stop at least 10⁻⁵), the focus distance, or with a focus object (and bone) the distance
between it and the camera along the camera's view axis; blades, rotation and ratio as set.
Orthographic depth of field is not supported (warning, rendered sharp).
"""
from __future__ import annotations

import numpy as np


class CameraExportError(Exception):
    """The camera cannot be rendered (missing, or a type the core lacks)."""


def render_size(render) -> tuple[int, int]:
    """Full-frame size in pixels: resolution × percentage, truncated like Blender."""
    pct = int(render.resolution_percentage)
    return (int(render.resolution_x) * pct // 100, int(render.resolution_y) * pct // 100)


def rigid(matrix) -> np.ndarray:
    """4×4 float64 copy of ``matrix`` with the scale taken out of its 3×3 part."""
    m = np.array(matrix, np.float64).reshape(4, 4)
    lengths = np.linalg.norm(m[:3, :3], axis=0)
    m[:3, :3] /= np.where(lengths > 0, lengths, 1.0)
    return m


def camera_desc(scene, camera_object, size: tuple[int, int] | None = None,
                use_border: bool | None = None):
    """``CameraDesc`` for ``camera_object`` (an evaluated or original camera object).

    Args:
        size: full-frame pixels (default: the scene's resolution × percentage).
        use_border: override ``render.use_border`` (previews never use a border).
    Returns:
        (CameraDesc, warnings)
    """
    from ercuts_core.description import CameraDesc

    if camera_object is None:
        raise CameraExportError(
            "no camera: the scene has no active camera (set Scene Properties > Camera)")
    if camera_object.type != "CAMERA":
        raise CameraExportError(f"active camera '{camera_object.name}' is not a camera object")
    cam = camera_object.data
    if cam.type not in {"PERSP", "ORTHO"}:
        raise CameraExportError(f"camera '{camera_object.name}': {cam.type} cameras are not supported "
                                "(use Perspective or Orthographic)")
    render = scene.render
    width, height = size if size is not None else render_size(render)
    warnings = []
    lens = _lens(camera_object, warnings)
    if use_border is None:
        use_border = bool(render.use_border)
    desc = CameraDesc(
        world_from_camera=rigid(camera_object.matrix_world),
        width=width, height=height,
        projection=cam.type,
        lens=float(cam.lens),
        sensor_width=float(cam.sensor_width),
        sensor_height=float(cam.sensor_height),
        sensor_fit=cam.sensor_fit,
        shift_x=float(cam.shift_x), shift_y=float(cam.shift_y),
        ortho_scale=float(cam.ortho_scale),
        pixel_aspect_x=float(render.pixel_aspect_x),
        pixel_aspect_y=float(render.pixel_aspect_y),
        border=(float(render.border_min_x), float(render.border_min_y),
                float(render.border_max_x), float(render.border_max_y)),
        use_border=use_border,
        clip_start=float(cam.clip_start), clip_end=float(cam.clip_end),
        **lens,
    )
    return desc, warnings


def _lens(camera_object, warnings: list[str]) -> dict:
    """The CameraDesc thin-lens fields of a camera object (empty without depth of field)."""
    cam = camera_object.data
    dof = getattr(cam, "dof", None)
    if dof is None or not dof.use_dof:
        return {}
    if cam.type == "ORTHO":
        warnings.append(f"Camera '{camera_object.name}': orthographic depth of field is not "
                        "supported; rendered sharp")
        return {}
    return dict(aperture_radius=float(cam.lens) * 1e-3 / (2.0 * max(float(dof.aperture_fstop), 1e-5)),
                focus_distance=focus_distance(camera_object),
                aperture_blades=int(dof.aperture_blades), aperture_rotation=float(dof.aperture_rotation),
                aperture_ratio=float(dof.aperture_ratio))


def focus_distance(camera_object) -> float:
    """Cycles ``blender_camera_focal_distance``: ``dof.focus_distance``, or with a focus object
    |view axis · (camera − target)|, the target being the object's origin or the head of its
    ``focus_subtarget`` bone."""
    dof = camera_object.data.dof
    target = dof.focus_object
    if target is None:
        return float(dof.focus_distance)
    m = np.array(target.matrix_world, np.float64)
    bone = getattr(dof, "focus_subtarget", "")
    pose = getattr(target, "pose", None)
    if bone and pose is not None and bone in pose.bones:
        m = m @ np.array(pose.bones[bone].matrix, np.float64)
    cam = rigid(camera_object.matrix_world)
    return float(abs(cam[:3, 2] @ (cam[:3, 3] - m[:3, 3])))
