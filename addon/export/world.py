"""Blender world → background radiance (W·sr⁻¹·m⁻²): a constant, or an HDRI map.

A Background node driving the world output gives Color × Strength (the colour may
come from an RGB node); a world without nodes gives ``world.color``; no world is
black.

Environment Texture (equirectangular) feeding the Background's Color becomes a
``WorldMap``: the image's pixels (``Image.pixels``, bottom row first, as the core
expects) in linear RGB × Strength — float images (EXR, HDR, float generated images) are
already linear; byte images in the sRGB colour space are converted with the sRGB
transfer function (IEC 61966-2-1), Non-Color/linear byte images are taken as they are.
The texture's Vector may come from a Mapping node (its rotation, Euler XYZ; Point,
Vector and Normal types rotate by R, Texture by Rᵀ; location and scale of a direction
are ignored with a note) fed by Texture Coordinate Generated/Object (the ray direction;
an Object output with an object set applies that object's inverse rotation). A missing
or empty image renders magenta like Cycles, with a warning.

Anything else (Sky Texture, mirror-ball projection, mixes, other vector nodes) is reported
once and falls back to the Background node's own colour (the average colour a user set),
or ``world.color``; Closest/Cubic/Smart interpolation render as Linear with a note.
"""
from __future__ import annotations

import numpy as np

from .. import compat
from .images import read_image
from .materials import _Reader, follow_link, output_node

#: Cycles' colour for a missing texture (TEX_IMAGE_MISSING_R/G/B).
MISSING_TEXTURE_RGB = (1.0, 0.0, 1.0)


def world_radiance(world) -> tuple[np.ndarray, list[str]]:
    """(3,) float32 radiance and the warnings for ``world`` (None → black); an environment
    texture gives its mean colour here (:func:`world_background` keeps the map)."""
    radiance, _, warnings = world_background(world)
    return radiance, warnings


def world_background(world):
    """(radiance (3,) float32, WorldMap | None, warnings) for ``world`` (None → black).

    With a map, ``radiance`` is the map's solid-angle mean (× strength): the constant the
    core falls back to if the map is unusable.
    """
    if world is None:
        return np.zeros(3, np.float32), None, []
    fallback = np.array(world.color[:3], np.float32)
    if not compat.uses_nodes(world):
        return fallback, None, []
    reader = _Reader(world.name)
    out = output_node(world.node_tree)
    node, _ = follow_link(out.inputs.get("Surface")) if out is not None else (None, None)
    if node is None:
        # An output with nothing connected renders black in Cycles.
        return np.zeros(3, np.float32), None, []
    world_map = None
    if node.bl_idname == "ShaderNodeBackground":
        strength = np.float32(reader.scalar(node.inputs.get("Strength"), 1.0))
        color_in = node.inputs.get("Color")
        tex, _ = follow_link(color_in)
        if tex is not None and tex.bl_idname == "ShaderNodeTexEnvironment":
            own = tuple(float(c) for c in color_in.default_value[:3])   # the socket's own colour
            radiance, world_map = _environment(tex, strength, reader, own)
        else:
            color = np.array(reader.color(color_in, tuple(fallback)), np.float32)
            radiance = color * strength
    else:
        reader.note(f"unsupported node '{node.name}' ({node.bl_idname}), using the world colour")
        radiance = fallback
    warnings = [f"World '{world.name}': " + "; ".join(reader.notes)] if reader.notes else []
    return np.maximum(radiance, 0.0).astype(np.float32), world_map, warnings


# --------------------------------------------------------------------------- environment texture

def _environment(tex, strength, reader: _Reader, fallback):
    """(mean radiance (3,), WorldMap or None) of an Environment Texture node × ``strength``."""
    from ercuts_core.description import WorldMap

    if getattr(tex, "projection", "EQUIRECTANGULAR") != "EQUIRECTANGULAR":
        reader.note(f"environment projection '{tex.projection}' is not supported, using the "
                    "Background colour")
        return np.array(fallback, np.float32) * strength, None
    if getattr(tex, "interpolation", "Linear") != "Linear":
        reader.note(f"environment interpolation '{tex.interpolation}' rendered as Linear")
    pixels = image_pixels(tex.image, reader)
    if pixels is None:
        name = tex.image.name if tex.image is not None else "<none>"
        reader.note(f"environment image '{name}' is missing or empty, rendered magenta")
        return np.array(MISSING_TEXTURE_RGB, np.float32) * strength, None
    rotation = _vector_rotation(tex.inputs.get("Vector"), reader)
    radiance = pixels * strength
    if isinstance(rotation, tuple):              # a constant vector: one texel everywhere
        from ercuts_core.envmap import EnvMap, direction_to_uv
        d = np.asarray(rotation[1], np.float64).reshape(1, 3)
        u, v = direction_to_uv(d) if np.any(d != 0) else (np.zeros(1), np.zeros(1))
        return EnvMap(radiance).lookup_uv(u, v)[0].astype(np.float32), None
    H = radiance.shape[0]
    sin_row = np.sin(np.pi * (np.arange(H) + 0.5) / H)          # solid-angle weight of a row
    mean = (radiance.mean(axis=1) * sin_row[:, None]).sum(0) / sin_row.sum()
    return mean.astype(np.float32), WorldMap(radiance, rotation)


def image_pixels(image, reader: _Reader) -> np.ndarray | None:
    """(H, W, 3) float32 linear RGB of a Blender image (bottom row first), read by the
    texture table's :func:`~.images.read_image`, alpha ignored: the stored colour (float
    images keep their stored, associated values; byte images their straight colour), or
    None when it has no pixels."""
    if image is None:
        return None
    straight, associated, notes = read_image(image)
    for note in notes:
        reader.note(f"environment image '{image.name}': {note}")
    if straight is None:
        return None
    rgba = associated if associated is not None and image.is_float else straight
    return np.ascontiguousarray(rgba[..., :3])


def _euler_xyz(rx: float, ry: float, rz: float) -> np.ndarray:
    """Blender's Euler XYZ rotation matrix R = Rz·Ry·Rx (``eul_to_mat3``)."""
    cx, sx, cy, sy, cz, sz = np.cos(rx), np.sin(rx), np.cos(ry), np.sin(ry), np.cos(rz), np.sin(rz)
    Rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    Ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    Rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    return Rz @ Ry @ Rx


def _vector_rotation(socket, reader: _Reader):
    """(3, 3) world → map rotation of the Environment Texture's Vector input, or
    ("constant", vector) when the lookup vector does not depend on the direction."""
    node, out = follow_link(socket)
    rotation = np.eye(3)
    if node is not None and node.bl_idname == "ShaderNodeMapping":
        mapping = node
        rotation = _mapping_rotation(mapping, reader)
        node, out = follow_link(mapping.inputs.get("Vector"))
        if node is None:
            # Cycles: an unlinked Mapping input is the constant (0, 0, 0), not the direction
            reader.note(f"Mapping '{mapping.name}' has no input vector: one texel lights the "
                        "whole world, as in Cycles")
            loc = reader.value(mapping.inputs.get("Location"), (0.0, 0.0, 0.0))
            return ("constant", loc[:3] if mapping.vector_type == "POINT" else (0.0, 0.0, 0.0))
    if node is None:
        return rotation
    if node.bl_idname == "ShaderNodeTexCoord" and out.name in ("Generated", "Object"):
        obj = getattr(node, "object", None)
        if out.name == "Object" and obj is not None:
            m = np.array(obj.matrix_world, np.float64)
            u, _, vt = np.linalg.svd(m[:3, :3])              # the object's rotation, scale removed
            rotation = rotation @ (u @ vt).T
            if np.any(np.abs(m[:3, 3]) > 1e-6):
                reader.note(f"environment coordinates of object '{obj.name}': its location is ignored")
        return rotation
    reader.note(f"environment vector from unsupported node '{node.name}' ({node.bl_idname}), "
                "using the view direction")
    return rotation


def _mapping_rotation(node, reader: _Reader) -> np.ndarray:
    """(3, 3) rotation a Mapping node applies to a direction (Cycles svm_mapping)."""
    rot = reader.value(node.inputs.get("Rotation"), (0.0, 0.0, 0.0))
    R = _euler_xyz(*(float(a) for a in rot[:3]))
    kind = getattr(node, "vector_type", "POINT")
    loc = (reader.value(node.inputs.get("Location"), (0.0, 0.0, 0.0)) if kind in ("POINT", "TEXTURE")
           else (0.0, 0.0, 0.0))
    scale = reader.value(node.inputs.get("Scale"), (1.0, 1.0, 1.0))
    moved = np.any(np.abs(np.asarray(loc[:3], float)) > 1e-6)
    if moved or np.any(np.abs(np.asarray(scale[:3], float) - 1) > 1e-6):
        reader.note(f"Mapping '{node.name}': location and scale of the environment direction are ignored")
    return R.T if kind == "TEXTURE" else R
