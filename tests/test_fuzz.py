"""Property-based fuzzing of the core with random scene descriptions (hypothesis).

Thousands of random descriptions — NaN/Inf/huge/duplicate vertices, indices out of range,
zero-area triangles, materials with NaN or out-of-range values, lights with zero, negative
or non-finite parameters, missing or degenerate cameras, empty borders — go through
``validate.sanitize`` and ``BuiltScene``; a subset is rendered at 8×6 px, 1 spp, with each
integrator. The properties: nothing raises except :class:`SceneError`; every defect that
matters is reported as an issue (or counted); the clean description satisfies the core's
invariants; rendered images are finite, of the window's size, and no non-finite sample
reached the film.

Deterministic: the profile is derandomized (fixed seed, no example database), so CI runs
the same cases every time (about a minute in all).
"""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings, strategies as st

from ercuts_core import RenderSettings, SceneError, render
from ercuts_core.camera import render_window
from ercuts_core.description import (AreaLights, CameraDesc, MaterialTable, MeshTable, PointLights,
                                     SceneDescription, SunLights)
from ercuts_core.scene import BuiltScene
from ercuts_core.scenes import look_at
from ercuts_core.validate import sanitize

PROFILE = dict(derandomize=True, database=None, deadline=None,
               suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
#: Cases for validate + build, and renders per integrator.
N_BUILD = 2000
N_RENDER = 150
TINY = dict(samples=1, rough_samples=1, max_depth=3, chain_length=3, e1_samples=4, max_cut_size=16, batch_rays=4096,
            threads=1)

VERTEX_DEFECTS = ("nan", "inf", "huge", "duplicate")
MESH_DEFECTS = ("index_out_of_range", "negative_index", "zero_area", "material_out_of_range")
VALUES = st.sampled_from([0.0, 0.5, 1.0, 2.0, -1.0, 1e-30, 1e30, np.nan, np.inf, -np.inf])


@st.composite
def descriptions(draw, valid_camera: bool = False) -> tuple[SceneDescription, set[str]]:
    """A random description and the set of defects put into it (``valid_camera``: a
    camera that renders, so that the case reaches the integrators)."""
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    defects = set(draw(st.sets(st.sampled_from(VERTEX_DEFECTS + MESH_DEFECTS), max_size=3)))
    n_v, n_t = draw(st.integers(0, 12)), draw(st.integers(0, 16))
    scale = draw(st.sampled_from([1e-3, 1.0, 10.0]))
    pos = rng.normal(size=(n_v, 3)) * scale
    tris = rng.integers(0, max(n_v, 1), size=(n_t, 3))
    if n_v and n_t:
        row = rng.integers(0, n_v, size=1)
        if "nan" in defects:
            pos[row, rng.integers(0, 3)] = np.nan
        if "inf" in defects:
            pos[row, 0] = -np.inf
        if "huge" in defects:
            pos[row] = 3e38
        if "duplicate" in defects:
            pos[rng.integers(0, n_v)] = pos[row]
        if "index_out_of_range" in defects:
            tris[rng.integers(0, n_t), rng.integers(0, 3)] = n_v + 5
        if "negative_index" in defects:
            tris[rng.integers(0, n_t), 0] = -1
        if "zero_area" in defects:
            tris[rng.integers(0, n_t)] = [tris[0, 0]] * 3
    n_m = draw(st.integers(1, 3))
    mats = MaterialTable(
        tuple(f"M{i}" for i in range(n_m)),
        rng.choice([0.0, 0.5, 1.0, 2.0, np.nan, -1.0], size=(n_m, 3)),
        rng.choice([0.0, 1e-6, 0.3, 1.0, np.nan, 5.0], size=n_m),
        rng.choice([0.0, 1.0, np.nan], size=n_m), rng.choice([0.0, 0.5, 1.0], size=n_m),
        rng.choice([0.0, 0.0, 1.0, 50.0, np.inf, np.nan], size=(n_m, 3)))
    mat_ids = rng.integers(0, n_m, size=n_t)
    if "material_out_of_range" in defects and n_t:
        mat_ids[0] = n_m + 2
    n_obj = draw(st.integers(1, 3))
    smooth = draw(st.booleans())
    normals = rng.normal(size=(n_v, 3)) if smooth else None
    if normals is not None and n_v:
        normals[0] = draw(st.sampled_from([(0.0, 0.0, 0.0), (np.nan, 0.0, 1.0), (0.0, 0.0, 1.0)]))
    mesh = MeshTable(pos, tris, mat_ids, rng.integers(0, n_obj + 1, size=n_t), normals)
    n_p, n_s, n_a = (draw(st.integers(0, 2)) for _ in range(3))
    point = PointLights(rng.normal(size=(n_p, 3)) * scale,
                        [[draw(VALUES)] * 3 for _ in range(n_p)], rng.normal(size=(n_p, 3)),
                        rng.choice([-1.0, 0.5, 0.99, 1.0], size=n_p), rng.choice([0.0, 0.5, 1.0], size=n_p),
                        np.zeros(n_p), rng.integers(0, n_obj + 1, size=n_p))
    sun = SunLights([draw(st.sampled_from([(0.0, 0.0, -1.0), (0.0, 0.0, 0.0), (1.0, np.nan, 0.0)]))
                     for _ in range(n_s)], [[draw(VALUES)] * 3 for _ in range(n_s)], np.zeros(n_s),
                    np.zeros(n_s, int))
    area = AreaLights(rng.normal(size=(n_a, 3)), rng.normal(size=(n_a, 3)) * draw(VALUES),
                      rng.normal(size=(n_a, 3)), rng.normal(size=(n_a, 3)),
                      [[draw(VALUES)] * 3 for _ in range(n_a)], rng.integers(0, 2, size=n_a),
                      np.zeros(n_a, int))
    camera = None
    if valid_camera:
        eye = rng.normal(size=3) * 3 + [0, 0, 3]
        border = tuple(sorted(rng.random(2) * 0.5)) + (1.0,)
        camera = CameraDesc(look_at(eye, [0, 0, 0]), draw(st.integers(1, 8)), draw(st.integers(1, 6)),
                            projection=draw(st.sampled_from(["PERSP", "ORTHO"])),
                            use_border=draw(st.booleans()), border=(border[0], border[1], 1.0, 1.0))
    elif draw(st.integers(0, 9)) > 0:
        eye = rng.normal(size=3) * 3 + [0, 0, 3]
        m = look_at(eye, [0, 0, 0]) if draw(st.booleans()) else np.diag(
            [draw(st.sampled_from([1.0, 0.0, np.nan])), 1.0, 1.0, 1.0])
        border = tuple(sorted(rng.random(2))) if draw(st.booleans()) else (0.5, 0.5)
        camera = CameraDesc(m, draw(st.integers(0, 8)), draw(st.integers(0, 6)),
                            projection=draw(st.sampled_from(["PERSP", "ORTHO", "PANO"])),
                            lens=draw(st.sampled_from([35.0, 0.0, -5.0, np.nan])),
                            use_border=draw(st.booleans()), border=(border[0], border[0], border[1], border[1]))
    world = [draw(st.sampled_from([0.0, 0.1, 1.0, np.nan, np.inf]))] * 3
    desc = SceneDescription(mesh, mats, camera, point, sun, area, world,
                            object_names=tuple(f"Obj{i}" for i in range(n_obj)))
    return desc, defects


def referenced_bad_vertices(desc: SceneDescription) -> bool:
    """True if some in-range triangle uses a NaN/Inf vertex (must be reported)."""
    m = desc.mesh
    if m.n_triangles == 0:
        return False
    ok_idx = ((m.triangles >= 0) & (m.triangles < len(m.positions))).all(axis=1)
    finite = np.isfinite(m.positions).all(axis=1)
    return bool((~finite[m.triangles[ok_idx]]).any())


def check_clean(desc: SceneDescription, clean) -> None:
    """The invariants every later stage relies on."""
    m = clean.desc.mesh
    n_v, n_m = len(m.positions), clean.desc.materials.n_materials
    assert ((m.triangles >= 0) & (m.triangles < n_v)).all()
    if m.n_triangles:
        assert np.isfinite(m.positions[m.triangles]).all()
    assert ((m.material_ids >= 0) & (m.material_ids < n_m)).all()
    mats = clean.desc.materials
    for a in (mats.base_color, mats.roughness, mats.metallic, mats.specular, mats.emission):
        assert not np.isnan(a).any()
    for lights in (clean.desc.point_lights, clean.desc.sun_lights, clean.desc.area_lights):
        for name in ("position", "intensity", "direction", "irradiance", "center", "radiance", "normal"):
            if hasattr(lights, name):
                assert np.isfinite(getattr(lights, name)).all(), name
    assert np.isfinite(clean.desc.world_radiance).all()
    codes = {i.code for i in clean.issues}
    if referenced_bad_vertices(desc):
        assert "nonfinite_vertices" in codes or "index_out_of_range" in codes
    for issue in clean.issues:
        assert issue.severity in ("error", "warning", "info") and issue.message


@settings(max_examples=N_BUILD, **PROFILE)
@given(descriptions())
def test_validate_and_build_never_crash(case):
    desc, _ = case
    try:
        clean = sanitize(desc)
    except SceneError as exc:
        assert str(exc)
        return
    check_clean(desc, clean)
    scene = BuiltScene(clean.desc, threads=1)
    try:
        assert scene.camera.window.n_pixels == render_window(clean.desc.camera).n_pixels
    finally:
        scene.close()


@pytest.mark.parametrize("integrator", ["PATH", "BDPT", "ERCUTS"])
def test_tiny_renders_never_crash_nor_produce_nonfinite_pixels(integrator):
    rendered = []

    @settings(max_examples=N_RENDER, **PROFILE)
    @given(descriptions(valid_camera=True))
    def run(case):
        desc, _ = case
        try:
            result = render(desc, RenderSettings(integrator=integrator, **TINY))
        except SceneError as exc:
            assert str(exc)
            return
        rendered.append(result.image[..., :3].max() > 0)
        w = render_window(desc.camera)
        assert result.image.shape == (w.height, w.width, 4)
        assert np.isfinite(result.image).all()
        assert result.stats["nonfinite_samples"] == 0
        for aov in result.aovs.values():
            assert np.isfinite(aov).all()

    run()
    assert len(rendered) == N_RENDER and sum(rendered) >= N_RENDER // 4   # not vacuous
