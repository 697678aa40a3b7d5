"""Ercuts core: a pure numpy + embreex renderer for scenes lit mostly by indirect light.

Public API::

    from ercuts_core import render, RenderSettings, SceneDescription, load_npz, save_npz
    result = render(load_npz("scene.npz"), RenderSettings(samples=16))
    result.image            # (h, w, 4) float32 linear RGBA, top row first

This package never imports bpy: the Blender add-on hands it a :class:`SceneDescription`.
"""
from .description import (
                          AreaLights,
                          CameraDesc,
                          MaterialTable,
                          MeshTable,
                          PointLights,
                          SceneDescription,
                          SunLights,
                          load_npz,
                          save_npz,
)
from .render import render
from .shading.textures import TextureTable
from .result import RenderResult
from .settings import RenderSettings
from .validate import Issue, SceneError

__version__ = "0.1.0"

__all__ = [
    "AreaLights", "CameraDesc", "Issue", "MaterialTable", "MeshTable", "PointLights",
    "RenderResult", "RenderSettings", "SceneDescription", "SceneError", "SunLights",
    "TextureTable", "load_npz", "render", "save_npz", "__version__",
]
