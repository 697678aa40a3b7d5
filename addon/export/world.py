"""Blender world → constant background radiance (W·sr⁻¹·m⁻²).

A Background node driving the world output gives Color × Strength (the colour may
come from an RGB node); a world without nodes gives ``world.color``; no world is
black. Anything else (sky or environment textures, mixes) is reported once and
falls back to the Background node's own colour, or ``world.color``.
"""
from __future__ import annotations

import numpy as np

from .. import compat
from .materials import _Reader, follow_link, output_node


def world_radiance(world) -> tuple[np.ndarray, list[str]]:
    """(3,) float32 radiance and the warnings for ``world`` (None → black)."""
    if world is None:
        return np.zeros(3, np.float32), []
    fallback = np.array(world.color[:3], np.float32)
    if not compat.uses_nodes(world):
        return fallback, []
    reader = _Reader(world.name)
    out = output_node(world.node_tree)
    node, _ = follow_link(out.inputs.get("Surface")) if out is not None else (None, None)
    if node is None:
        # An output with nothing connected renders black in Cycles.
        return np.zeros(3, np.float32), []
    if node.bl_idname == "ShaderNodeBackground":
        color = np.array(reader.color(node.inputs.get("Color"), tuple(fallback)), np.float32)
        radiance = color * np.float32(reader.scalar(node.inputs.get("Strength"), 1.0))
    else:
        reader.note(f"unsupported node '{node.name}' ({node.bl_idname}), using the world colour")
        radiance = fallback
    warnings = [f"World '{world.name}': " + "; ".join(reader.notes)] if reader.notes else []
    return np.maximum(radiance, 0.0).astype(np.float32), warnings
