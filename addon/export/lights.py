"""Blender lights → the core's point, sun and area light tables, in Blender's units.

Conversions (shared docs ``blender.md`` §2.3, measured with Cycles on 3.4.1 and 5.0.1):

* rgb = colour · temperature tint · power · 2^exposure (· light-node Emission colour·strength)
* point/spot: radiant intensity I = rgb/(4π) W/sr (spot power is *not* concentrated
  into the cone; without ``normalize`` see :func:`..compat.point_light_intensity_scale`);
  spot half-angle = spot_size/2, smoothstep blend = spot_blend; radius = shadow_soft_size,
  a sphere when Soft Falloff is off (≥ 4.0), else the disk facing the receiver
* sun: irradiance E = rgb W/m² travelling along the light's local −Z, angle = its angular
  diameter
* area: radiance L = rgb/(π·A) (≥ 4.0), rgb/(4·A) (3.x), rgb/π without ``normalize``;
  A includes the object scale; SQUARE/RECTANGLE → rectangle, DISK/ELLIPSE → ellipse;
  emits along local −Z
"""
from __future__ import annotations

import math

import numpy as np

from .. import compat
from .materials import follow_link, output_node


def _unit(v: np.ndarray) -> np.ndarray:
    n = float(np.linalg.norm(v))
    return v / n if n > 0 else v


class LightCollector:
    """Accumulates light instances; :meth:`tables` builds the description's arrays."""

    def __init__(self):
        self.points: list[dict] = []
        self.suns: list[dict] = []
        self.areas: list[dict] = []
        self.warnings: list[str] = []

    def add(self, light, matrix: np.ndarray, object_id: int, name: str) -> None:
        """Add one light instance with its 4×4 world matrix (its object's ray visibility is
        :mod:`.visibility`'s)."""
        m = np.asarray(matrix, np.float64)
        rgb = self.light_rgb(light, name)
        position = m[:3, 3]
        down = _unit(m[:3, :3] @ np.array([0.0, 0.0, -1.0]))  # local −Z in the world
        kind = light.type
        if kind in {"POINT", "SPOT"}:
            spot = kind == "SPOT"
            if spot and compat.SPOT_COSINE_FALLOFF:
                # The description has no cos θ term yet (see compat.SPOT_COSINE_FALLOFF).
                self.warnings.append(
                    f"Light '{name}': Blender 3.x spot lights also dim by cos θ inside the cone; "
                    "Ercuts renders the Blender 4+ spot (no cosine), brighter off-axis")
            self.points.append(dict(
                position=position,
                intensity=rgb * compat.point_light_intensity_scale(light),
                direction=down,
                cos_half_angle=math.cos(light.spot_size / 2.0) if spot else -1.0,
                blend=float(light.spot_blend) if spot else 0.0,
                radius=float(light.shadow_soft_size),
                object_id=object_id,
                sphere=compat.point_light_is_sphere(light),
            ))
        elif kind == "SUN":
            self.suns.append(dict(direction=down, irradiance=rgb * compat.sun_irradiance_scale(light),
                                  angle=float(light.angle), object_id=object_id))
        elif kind == "AREA":
            self._add_area(light, m, rgb, object_id, name)
        else:
            self.warnings.append(f"Light '{name}': unsupported type {kind}, ignored")

    def _add_area(self, light, m, rgb, object_id, name) -> None:
        square = light.shape in {"SQUARE", "DISK"}
        size_x = float(light.size)
        size_y = size_x if square else float(light.size_y)
        axis_u = m[:3, 0] * (0.5 * size_x)
        axis_v = m[:3, 1] * (0.5 * size_y)
        ellipse = light.shape in {"DISK", "ELLIPSE"}
        # Area of the scaled shape: |u×v|·4 for the rectangle, ·π for the ellipse.
        cross = float(np.linalg.norm(np.cross(axis_u, axis_v)))
        area = cross * (math.pi if ellipse else 4.0)
        if area <= 0.0:
            self.warnings.append(f"Light '{name}': area light of zero size ignored")
            return
        from ercuts_core.description import SHAPE_ELLIPSE, SHAPE_RECT

        self.areas.append(dict(
            center=m[:3, 3],
            axis_u=axis_u,
            axis_v=axis_v,
            normal=_unit(-m[:3, 2]),
            radiance=rgb * compat.area_light_radiance_scale(light, area),
            shape=SHAPE_ELLIPSE if ellipse else SHAPE_RECT,
            object_id=object_id,
            spread=float(getattr(light, "spread", math.pi)),
        ))

    def light_rgb(self, light, name: str) -> np.ndarray:
        """colour · temperature · power · 2^exposure · light-node emission, as (3,) float64."""
        rgb = (np.array(light.color[:3], np.float64)
               * np.array(compat.light_temperature_rgb(light))
               * float(light.energy) * compat.light_exposure_scale(light))
        if compat.uses_nodes(light):
            rgb = rgb * self._node_emission(light, name)
        return rgb

    def _node_emission(self, light, name: str) -> np.ndarray:
        """Colour·Strength of the Emission node driving a light's node tree (1 otherwise)."""
        out = output_node(light.node_tree)
        node, _ = follow_link(out.inputs.get("Surface")) if out is not None else (None, None)
        if node is None:
            return np.ones(3)
        if node.bl_idname != "ShaderNodeEmission":
            self.warnings.append(f"Light '{name}': node '{node.name}' ({node.bl_idname}) ignored")
            return np.ones(3)
        color, strength = node.inputs.get("Color"), node.inputs.get("Strength")
        if color.is_linked or strength.is_linked:
            self.warnings.append(f"Light '{name}': linked light-node inputs ignored")
        return np.array(color.default_value[:3], np.float64) * float(strength.default_value)

    def tables(self):
        """(PointLights, SunLights, AreaLights) for the scene description."""
        from ercuts_core.description import AreaLights, PointLights, SunLights

        def col(rows, key, shape):
            return np.array([r[key] for r in rows], np.float64).reshape(shape)

        p, s, a = self.points, self.suns, self.areas
        points = PointLights(
            position=col(p, "position", (-1, 3)), intensity=col(p, "intensity", (-1, 3)),
            direction=col(p, "direction", (-1, 3)), cos_half_angle=col(p, "cos_half_angle", (-1,)),
            blend=col(p, "blend", (-1,)), radius=col(p, "radius", (-1,)),
            object_ids=np.array([r["object_id"] for r in p], np.int32),
            sphere=np.array([r["sphere"] for r in p], bool))
        suns = SunLights(
            direction=col(s, "direction", (-1, 3)), irradiance=col(s, "irradiance", (-1, 3)),
            angle=col(s, "angle", (-1,)), object_ids=np.array([r["object_id"] for r in s], np.int32))
        areas = AreaLights(
            center=col(a, "center", (-1, 3)), axis_u=col(a, "axis_u", (-1, 3)),
            axis_v=col(a, "axis_v", (-1, 3)), normal=col(a, "normal", (-1, 3)),
            radiance=col(a, "radiance", (-1, 3)),
            shape=np.array([r["shape"] for r in a], np.int32),
            object_ids=np.array([r["object_id"] for r in a], np.int32),
            spread=col(a, "spread", (-1,)))
        return points, suns, areas
