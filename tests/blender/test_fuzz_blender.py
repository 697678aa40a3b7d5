"""Random Blender scenes built with bpy, through the exporter and the engine (hypothesis).

Each case builds objects with random shapes, transforms (negative, zero and huge scales,
far locations), materials (diffuse, emission, Principled with random values, unsupported
shaders, no output node, empty slots), lights (every type, zero/negative power, zero
size) and an optional camera; then the exporter and the core's validation must either
succeed or fail with ExportError/SceneError (a message, never another exception), and a
subset is rendered with the engine at 8×6 px: it finishes, or refuses with one error line.
Derandomized: the same cases in every run (about half a minute).
"""
from __future__ import annotations

import math

import bpy
import numpy as np
from hypothesis import HealthCheck, given, settings, strategies as st

import blender_helpers as bh
from addon.export import ExportError

PROFILE = dict(derandomize=True, database=None, deadline=None,
               suppress_health_check=list(HealthCheck))
N_EXPORT = 100
N_RENDER = 25

SCALES = st.sampled_from([1.0, -1.0, 0.0, 1e-4, 1e4, 2.5])
LOCATIONS = st.sampled_from([0.0, 1.0, -3.0, 1e5])


def material(draw, i):
    kind = draw(st.sampled_from(["diffuse", "emission", "principled", "translucent", "no_output",
                                 "none"]))
    if kind == "none":
        return None
    if kind == "diffuse":
        return bh.diffuse(f"D{i}", color=tuple(draw(st.sampled_from([0.0, 0.5, 1.0])) for _ in range(3)))
    if kind == "emission":
        return bh.emission(f"E{i}", strength=draw(st.sampled_from([0.0, 1.0, 100.0, 1e6])))
    if kind == "principled":
        return bh.node_material(f"P{i}", "ShaderNodeBsdfPrincipled",
                                base_color=(0.8, 0.2, 0.2), Roughness=draw(st.sampled_from([0.0, 0.5, 1.0])),
                                Metallic=draw(st.sampled_from([0.0, 1.0])))
    if kind == "translucent":
        return bh.node_material(f"T{i}", "ShaderNodeBsdfTranslucent")
    mat = bh.diffuse(f"N{i}")
    for node in list(mat.node_tree.nodes):
        if node.bl_idname == "ShaderNodeOutputMaterial":
            mat.node_tree.nodes.remove(node)
    return mat


@st.composite
def blender_scenes(draw):
    """Build a random scene in the current (empty) Blender file; returns a short summary."""
    bh.setup_render(8, 6, samples=1, integrator=draw(st.sampled_from(["PATH", "BDPT", "ERCUTS"])),
                    max_depth=3)
    s = bpy.context.scene
    s.ercuts.chain_length, s.ercuts.e1_samples, s.ercuts.max_cut_size = 3, 4, 16
    summary = []
    for i in range(draw(st.integers(0, 4))):
        shape = draw(st.sampled_from(["plane", "box", "sphere", "empty_mesh", "sliver"]))
        mat = material(draw, i)
        if shape == "plane":
            obj = bh.plane(f"O{i}", size=draw(st.sampled_from([0.0, 1.0, 10.0])), material=mat)
        elif shape == "box":
            obj = bh.box(f"O{i}", material=mat, inward=draw(st.booleans()))
        elif shape == "sphere":
            obj = bh.uv_sphere(f"O{i}", segments=8, rings=4, material=mat)
        elif shape == "empty_mesh":
            obj = bh.mesh_object(f"O{i}", [(0, 0, 0)], [])
        else:
            obj = bh.mesh_object(f"O{i}", [(0, 0, 0), (1, 0, 0), (2, 0, 0)], [(0, 1, 2)], material=mat)
        obj.scale = tuple(draw(SCALES) for _ in range(3))
        obj.location = tuple(draw(LOCATIONS) for _ in range(3))
        obj.rotation_euler = (draw(st.floats(0, 2 * math.pi)), 0.0, 0.0)
        summary.append(f"{shape}:{mat.name if mat else None}:{tuple(obj.scale)}")
    for i in range(draw(st.integers(0, 3))):
        kind = draw(st.sampled_from(["POINT", "SPOT", "SUN", "AREA"]))
        extra = {}
        if kind == "AREA":
            extra = dict(size=draw(st.sampled_from([0.0, 0.5, 2.0])), shape=draw(st.sampled_from(["SQUARE", "DISK"])))
        light = bh.light(kind, location=(0, 0, draw(st.sampled_from([0.5, 3.0, 1e5]))),
                         energy=draw(st.sampled_from([0.0, 10.0, 1000.0, -5.0])), name=f"L{i}", **extra)
        light.scale = tuple(draw(SCALES) for _ in range(3))
        summary.append(f"light:{kind}")
    if draw(st.integers(0, 9)) > 0:
        bh.camera(location=(draw(LOCATIONS), -4.0, 3.0), target=(0, 0, 0),
                  type=draw(st.sampled_from(["PERSP", "ORTHO"])))
    return summary


def _fresh():
    bpy.ops.wm.read_factory_settings(use_empty=True)


@settings(max_examples=N_EXPORT, **PROFILE)
@given(data=st.data())
def test_random_scenes_export_and_validate_or_fail_cleanly(data):
    from ercuts_core import SceneError
    from ercuts_core.validate import sanitize

    _fresh()
    data.draw(blender_scenes())
    try:
        exported = bh.export()
    except ExportError as exc:
        assert "camera" in str(exc).lower() and "\n" not in str(exc)
        return
    desc = exported.description
    assert all(isinstance(w, str) and w for w in exported.warnings)
    try:
        clean = sanitize(desc)
    except SceneError as exc:
        assert str(exc)
        return
    assert np.isfinite(clean.desc.mesh.positions[clean.desc.mesh.triangles]).all()


def test_random_scenes_render_or_refuse_with_one_line(tmp_path):
    from addon import engine

    outcomes = []

    @settings(max_examples=N_RENDER, **PROFILE)
    @given(data=st.data())
    def run(data):
        _fresh()
        data.draw(blender_scenes())
        path = tmp_path / f"f{len(outcomes)}.exr"
        try:
            img = bh.render_exr(path)
        except RuntimeError as exc:
            message = str(exc).strip()
            assert "\n" not in message and "Traceback" not in message, message
            assert not path.exists()
            outcomes.append("refused")
            return
        assert np.isfinite(img).all()
        assert engine.last_render["stats"]["nonfinite_samples"] == 0
        outcomes.append("rendered")

    run()
    assert outcomes.count("rendered") >= N_RENDER // 2, outcomes     # not vacuous
