"""The translucent lobe of ercuts_core.bsdf (Cycles' Translucent BSDF; issue 15).

f(wo, wi) = kdt/π for wo and wi on opposite sides of the surface, sampled cosine-weighted
about the far side of the normal (pdf |cos|/π, Cycles' ``bsdf_translucent``), mixed with the
Lambert, GGX and glass lobes by one-sample MIS. Tested as the other lobes are:

* chi² of sample() against pdf() over the whole sphere (pure, mixed with Lambert, with GGX,
  with rough glass), and a wrong pdf that the test must reject;
* sample weight = f·|cos|/pdf; reciprocity f(wo, wi) = f(wi, wo); the adjoint is the same;
* white furnace (translucency 1, white: every sample weight 1, all of it below the surface)
  and a half-translucent Lambert (mean weight = the analytic albedo, half transmitted);
* finite values at grazing angles; the layer shares; the flags (not delta, not specular or
  glass, not reflect-only), ``bsdf_max_value`` and the lightcut bound at translucent
  receivers (VPLs on both sides; numpy and the compiled kernel agree);
* the ``translucency`` column: npz round trip, defaults, validation;
* end to end: a translucent panel in front of a large emitter (PATH, BDPT and ERCUTS against
  the analytic radiance C·Le·F, F the emitter's view factor) and a panel lit from behind by a
  wall an area light shines on (all of its light indirect: ERCUTS's VPLs on the wall, gathered
  through the panel), PATH, BDPT and ERCUTS agreeing in energy; and that these comparisons
  fail when the gather or BDPT treat the panel as opaque.
"""
from __future__ import annotations

import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))
from stats import SphericalDomain, chi2_test, frame_from_pole  # noqa: E402
from vpl_cases import random_vpls, receiver_points, unit  # noqa: E402

from ercuts_core.bsdf import Bsdf, bsdf_max_value  # noqa: E402
from ercuts_core.description import (AreaLights, CameraDesc, MaterialTable, MeshTable,  # noqa: E402
                                     SceneDescription, load_npz, save_npz)
from ercuts_core.render import render  # noqa: E402
from ercuts_core.sampling import coordinate_system  # noqa: E402
from ercuts_core.scenes import look_at  # noqa: E402
from ercuts_core.settings import RenderSettings  # noqa: E402

N = np.array([0.3, -0.5, 0.8]) / np.linalg.norm([0.3, -0.5, 0.8])
COLOR = (0.9, 0.6, 0.3)


def bsdf(n, translucency=1.0, color=COLOR, rough=1.0, spec=0.0, trans=0.0, metal=0.0, ior=1.5):
    return Bsdf.from_params(np.tile(color, (n, 1)), np.full(n, rough), np.full(n, metal),
                            np.full(n, spec), np.tile(N, (n, 1)), np.tile(N, (n, 1)),
                            transmission=np.full(n, trans), ior=np.full(n, ior),
                            translucency=np.full(n, translucency))


def direction(cos_t, phi, n=N):
    t, b = coordinate_system(n[None, :])
    s = np.sqrt(max(0.0, 1.0 - cos_t * cos_t))
    return (s * np.cos(phi) * t + s * np.sin(phi) * b + cos_t * n[None, :])[0]


# name: (translucency, roughness, specular, transmission, cos_o, wo inside)
CASES = {
    "pure": (1.0, 1.0, 0.0, 0.0, 0.7, False),
    "pure_from_inside": (1.0, 1.0, 0.0, 0.0, 0.3, True),
    "lambert_half": (0.5, 1.0, 0.0, 0.0, 0.5, False),
    "ggx": (0.4, 0.3, 0.5, 0.0, 0.6, False),
    "rough_glass": (0.3, 0.4, 0.5, 0.5, 0.8, True),
}


@pytest.mark.parametrize("case", list(CASES))
def test_sample_matches_pdf_chi2(case):
    tl, rough, spec, trans, cos_o, inside = CASES[case]
    wo = direction(cos_o, 1.3) * (-1.0 if inside else 1.0)

    def make(n):
        return bsdf(n, tl, rough=rough, spec=spec, trans=trans)

    def sample(u):
        s = make(len(u)).sample(np.tile(wo, (len(u), 1)), u)
        return s.wi, s.valid

    def pdf(w):
        return make(len(w)).pdf(np.tile(wo, (len(w), 1)), w)
    ok, msg = chi2_test(sample, pdf, n_samples=300_000, sample_dim=3, seed=31,
                        test_count=len(CASES) + 1, domain=SphericalDomain(frame_from_pole(-wo)))
    print(case, msg)
    assert ok, msg


def test_chi2_detects_a_wrong_translucent_pdf():
    """The pdf of translucency 0.35 for samples of 0.5 (the hemispheres' shares 0.35/0.65
    instead of 0.5/0.5): rejected."""
    wo = direction(0.5, 1.3)

    def sample(u):
        s = bsdf(len(u), 0.5).sample(np.tile(wo, (len(u), 1)), u)
        return s.wi, s.valid

    def pdf(w):
        return bsdf(len(w), 0.35).pdf(np.tile(wo, (len(w), 1)), w)
    ok, msg = chi2_test(sample, pdf, n_samples=300_000, sample_dim=3, seed=31,
                        test_count=len(CASES) + 1, domain=SphericalDomain(frame_from_pole(-wo)))
    print(msg)
    assert not ok


@pytest.mark.parametrize("adjoint", [False, True])
@pytest.mark.parametrize("case", ["lambert_half", "ggx", "rough_glass"])
def test_weight_is_f_cos_over_pdf(case, adjoint):
    tl, rough, spec, trans, cos_o, inside = CASES[case]
    n = 20_000
    b = bsdf(n, tl, rough=rough, spec=spec, trans=trans)
    wo = np.tile(direction(cos_o, 0.4) * (-1.0 if inside else 1.0), (n, 1))
    s = b.sample(wo, np.random.default_rng(2).random((n, 3)), adjoint=adjoint)
    v = s.valid
    assert v.mean() > 0.9 and not s.is_delta.any()
    f, pdf = b.subset(v).eval_pdf(wo[v], s.wi[v], adjoint=adjoint)
    np.testing.assert_allclose(s.pdf[v], pdf, rtol=1e-10)
    np.testing.assert_allclose(s.weight[v], f * (np.abs(s.wi[v] @ N) / pdf)[:, None], rtol=1e-10)
    # the far side gets the translucent lobe's share (and the glass's, for rough glass)
    far = ((s.wi[v] @ N) * (wo[v] @ N)) < 0
    assert 0.2 < far.mean() < 0.9


def test_reciprocal_and_adjoint_is_the_same_function():
    rng = np.random.default_rng(4)
    m = 4000
    b = bsdf(m, 0.6, rough=0.5, spec=0.5)
    wo = unit(rng.normal(size=(m, 3)))
    wi = unit(rng.normal(size=(m, 3)))
    f = b.eval(wo, wi)
    opposite = (wo @ N) * (wi @ N) < 0
    assert (f[opposite] > 0).all() and opposite.mean() > 0.4
    np.testing.assert_array_equal(f, b.eval(wi, wo))                      # bit for bit
    np.testing.assert_array_equal(f, b.eval(wo, wi, adjoint=True))
    np.testing.assert_allclose(f[opposite], np.tile(b.kdt[0] / np.pi, (opposite.sum(), 1)), rtol=1e-15)


@pytest.mark.parametrize("cos_o,inside", [(0.9, False), (0.2, False), (0.6, True)])
def test_white_furnace(cos_o, inside):
    """Translucency 1, white: every sample carries weight 1 exactly, all of it into the far
    hemisphere; and ∫ f·|cos| dω = 1 by uniform sphere sampling (independent of sample())."""
    n = 100_000
    b = bsdf(n, 1.0, color=(1.0, 1.0, 1.0))
    wo_1 = direction(cos_o, 0.7) * (-1.0 if inside else 1.0)
    wo = np.tile(wo_1, (n, 1))
    s = b.sample(wo, np.random.default_rng(6).random((n, 3)))
    assert s.valid.mean() > 0.9999
    np.testing.assert_allclose(s.weight[s.valid], 1.0, rtol=1e-12)
    assert ((s.wi[s.valid] @ N) * (wo_1 @ N) < 0).all()
    np.testing.assert_allclose(b.albedo(), 1.0)
    wi = unit(np.random.default_rng(7).normal(size=(n, 3)))
    e = b.eval(wo, wi)[:, 0] * np.abs(wi @ N) * 4.0 * np.pi
    se = e.std() / np.sqrt(n)
    assert abs(e.mean() - 1.0) < 4.0 * se, (e.mean(), se)
    below = ((wi @ N) * (wo_1 @ N)) < 0
    assert (e[~below] == 0).all()


def test_half_translucent_lambert_mean_weight_is_the_albedo():
    """Translucency 0.5 on a coloured Lambert: kd = kdt = C/2, each lobe chosen with
    probability ½ (both ∝ Y(C)), so every weight is C and half the samples go through."""
    n = 100_000
    b = bsdf(n, 0.5)
    wo = np.tile(direction(0.4, 2.0), (n, 1))
    s = b.sample(wo, np.random.default_rng(8).random((n, 3)))
    v = s.valid
    np.testing.assert_allclose(b.kd[0], 0.5 * np.array(COLOR), rtol=1e-15)
    np.testing.assert_allclose(b.kdt[0], 0.5 * np.array(COLOR), rtol=1e-15)
    np.testing.assert_allclose(s.weight[v], np.tile(COLOR, (v.sum(), 1)), rtol=1e-12)
    through = (s.wi[v] @ N) < 0
    z = (through.mean() - 0.5) / np.sqrt(0.25 / v.sum())
    assert abs(z) < 4.0, z
    np.testing.assert_allclose(b.albedo()[0], COLOR, rtol=1e-12)


def test_translucent_with_ggx_transmits_kdt():
    """With a GGX coat (specular 0.5, roughness 0.3) the transmitted energy is kdt exactly:
    the mean of weight·[below] over many samples, within 4 standard errors."""
    n = 200_000
    b = bsdf(n, 0.5, rough=0.3, spec=0.5)
    wo = np.tile(direction(0.5, 2.0), (n, 1))
    s = b.sample(wo, np.random.default_rng(9).random((n, 3)))
    t = s.weight * ((s.wi @ N) < 0)[:, None]
    mean, se = t.mean(axis=0), t.std(axis=0) / np.sqrt(n)
    np.testing.assert_allclose(b.kdt[0], 0.5 * np.array(COLOR))
    assert np.all(np.abs(mean - b.kdt[0]) < 4.0 * se), (mean, b.kdt[0], se)
    r = s.weight[:, 0] * ((s.wi @ N) > 0)
    assert r.mean() < b.kd[0, 0] + b.f0[0, 0] + 4.0 * r.std() / np.sqrt(n)   # no energy gain


def test_layer_shares_add():
    """tl' = min(tl, 1 − t): Mix(Glass, Translucent, f) (t = 1 − f, tl = f) has no opaque part;
    metallic takes its share from all; the probabilities sum to 1."""
    b = Bsdf.from_params(np.full((4, 3), 0.5), 0.5, [0.0, 0.0, 0.5, 0.0], 0.5,
                         np.tile(N, (4, 1)), np.tile(N, (4, 1)), transmission=[0.7, 0.7, 0.0, 0.0],
                         translucency=[0.3, 0.9, 1.0, 0.0])
    np.testing.assert_allclose(b.kd[:2], 0.0, atol=1e-15)             # 1 − 0.7 − 0.3 = 0; capped
    np.testing.assert_allclose(b.kdt[:, 0], [0.15, 0.15, 0.25, 0.0])
    np.testing.assert_allclose(b.kt[:, 0], [0.35, 0.35, 0.0, 0.0])
    p_diff = 1.0 - b.p_spec - b.p_tr - b.p_dt
    assert np.all(p_diff >= -1e-15) and np.all(b.p_dt >= 0)
    assert b.p_dt[3] == 0.0 and b.kdt[3].max() == 0.0


def test_opaque_materials_are_unchanged_bit_for_bit():
    """translucency 0 gives the BSDF of before (fields, eval, pdf, sample)."""
    rng = np.random.default_rng(10)
    n = 500
    args = (rng.random((n, 3)), rng.random(n), rng.random(n) * (rng.random(n) < 0.5), rng.random(n),
            np.tile(N, (n, 1)), np.tile(N, (n, 1)))
    kw = dict(transmission=rng.random(n) * (rng.random(n) < 0.5), ior=1.5)
    a = Bsdf.from_params(*args, **kw)
    b = Bsdf.from_params(*args, **kw, translucency=0.0)
    for f in ("kd", "f0", "f90", "kt", "p_spec", "p_tr", "kr"):
        np.testing.assert_array_equal(getattr(a, f), getattr(b, f))
    assert not b.has_translucent and (b.p_dt == 0).all()
    wo, wi = unit(rng.normal(size=(n, 3))), unit(rng.normal(size=(n, 3)))
    u = rng.random((n, 3))
    np.testing.assert_array_equal(a.eval_pdf(wo, wi)[0], b.eval_pdf(wo, wi)[0])
    np.testing.assert_array_equal(a.sample(wo, u).weight, b.sample(wo, u).weight)


def test_finite_at_grazing_and_degenerate_inputs():
    n = 6
    b = bsdf(n, 0.7, rough=0.2, spec=0.5)
    g = direction(1e-11, 0.2)                 # below COS_EPS = 1e-10: on the horizon
    wo = np.array([g, -g, N, -N, direction(0.5, 1.0), direction(1e-9, 0.2)])
    wi = np.array([-direction(1e-11, 2.0), direction(1e-11, 2.0), -N, N, -direction(0.5, 4.1),
                   -direction(1e-9, 2.0)])
    with np.errstate(all="raise", under="ignore"):
        f, pdf = b.eval_pdf(wo, wi)
        s = b.sample(wo, np.array([[0.9, 0.5, 0.5]] * 3 + [[0.99, 1 - 1e-16, 0.0]] * 3))
    assert np.isfinite(f).all() and np.isfinite(pdf).all()
    assert np.isfinite(s.weight).all() and np.isfinite(s.pdf).all()
    assert f[2].max() > 0 and f[3].max() > 0 and f[4].max() > 0        # straight through
    assert f[0].max() == 0 and f[1].max() == 0                          # on the horizon: nothing
    np.testing.assert_allclose(f[5], 0.7 * np.array(COLOR) / np.pi)     # nearly grazing: kdt/π


def test_flags_and_max_value():
    """A translucent lane is not delta, not specular or glass (not even mixed with smooth glass
    and no diffuse part), not reflect-only; ``bsdf_max_value`` bounds kdt/π."""
    up = np.tile([0.0, 0.0, 1.0], (4, 1))
    # lane 1: a smooth metal share 0.5 and translucency 1 (no diffuse part); lane 2: smooth glass
    # 0.5 and translucency 0.5 (no diffuse part either)
    b = Bsdf.from_params(np.full((4, 3), 0.8), [1.0, 0.0, 0.0, 1.0], [0.0, 0.5, 0.0, 0.0], 0.0, up, up,
                         transmission=[0.0, 0.0, 0.5, 0.0], translucency=[1.0, 1.0, 0.5, 0.0])
    assert b.kd[1:3].max() == 0.0 and b.delta[1:3].all()
    assert b.translucent.tolist() == [True, True, True, False]
    assert b.reflect_only.tolist() == [False, False, False, True]
    assert not b.is_delta.any() and not b.is_specular_or_glass.any()
    # the same without translucency: a mirror and smooth glass are delta
    c = Bsdf.from_params(np.full((4, 3), 0.8), [1.0, 0.0, 0.0, 1.0], [0.0, 1.0, 0.0, 0.0], 0.0, up, up,
                         transmission=[0.0, 0.0, 1.0, 0.0])
    assert c.is_delta.tolist() == [False, True, True, False]
    table = MaterialTable(["t", "d"], [[0.9, 0.6, 0.3], [0.9, 0.6, 0.3]], [1, 1], [0, 0], [0, 0],
                          np.zeros((2, 3)), (), [0, 0], [1.5, 1.5], [1.0, 0.0])
    np.testing.assert_allclose(bsdf_max_value(table, [0, 1]), np.array([COLOR, COLOR]) / np.pi)


# --------------------------------------------------------------------------- lightcut bound

def translucent_points(n, seed):
    """Receivers as the gather builds them (lightcut normal on wo's side, transmissive): pure
    translucent Lambert, translucent + glossy GGX, translucent + rough glass."""
    rng = np.random.default_rng(seed)
    nrm = unit(rng.normal(size=(n, 3)))
    wo = unit(rng.normal(size=(n, 3)))
    wo = np.where(((wo * nrm).sum(1) < 0)[:, None], -wo, wo)
    kind = np.arange(n) % 3
    table = MaterialTable([f"m{i}" for i in range(n)], rng.uniform(0.2, 1.0, (n, 3)),
                          np.where(kind == 0, 1.0, rng.uniform(0.1, 0.6, n)), np.zeros(n),
                          np.where(kind == 0, 0.0, 0.5), np.zeros((n, 3)), (),
                          np.where(kind == 2, 0.5, 0.0), np.full(n, 1.5), rng.uniform(0.3, 1.0, n))
    x = rng.random((n, 3)) * 6.0 - 3.0
    return receiver_points(table, x, nrm, wo, transmissive=np.ones(n, bool))


@pytest.mark.parametrize("backend", ["numba", "numpy"])
def test_cluster_bound_dominates_every_member_at_translucent_receivers(backend):
    """L̄_C ≥ max over a cluster's VPLs of Y(f·|cos|·G ⊙ I_C), VPLs on both sides of the
    receivers; without the translucent term in the glossy/glass bound it is exceeded."""
    from ercuts_core import kernels
    from ercuts_core.integrators.ercuts.light_tree import build_light_tree
    from tests.test_glossy_bound import bound_table, violations, worst_member
    if backend == "numba" and not kernels.NUMBA:
        pytest.skip("numba not available")
    lights = random_vpls(400, 71, scale=8.0, shift=-4.0)
    tree = build_light_tree(*lights, seed=3)
    pts = translucent_points(150, 5)
    worst = worst_member(tree, lights, pts)
    without = replace(pts, glossy=replace(pts.glossy, kdt_pi=None))
    with kernels.backend(backend):
        bad, lit, ratio = violations(bound_table(tree, pts), worst)
        bad_w, _, ratio_w = violations(bound_table(tree, without), worst)
    print(f"{backend}: {lit} lit pairs; bound exceeded in {bad} (worst {ratio:.3g}); without "
          f"the translucent term in {bad_w} (worst ×{ratio_w:.3g})")
    assert bad == 0 and lit > 1000
    assert bad_w > 0


def test_lightcut_matches_numpy_at_translucent_receivers():
    from ercuts_core import kernels
    from ercuts_core.integrators.ercuts.light_tree import build_light_tree
    from ercuts_core.integrators.ercuts.lightcuts import lightcut
    if not kernels.NUMBA:
        pytest.skip("numba not available")
    pos, nrm, inten = random_vpls(1500, 6, scale=8.0, shift=-4.0)
    tree = build_light_tree(pos, nrm, inten, seed=0)
    pts = translucent_points(150, 41)
    out = []
    for name in ("numba", "numpy"):
        with kernels.backend(name):
            out.append(lightcut(tree, pos, nrm, inten, pts, error_mode="total", return_cut=True))
    a, b = out
    np.testing.assert_allclose(a.radiance, b.radiance, rtol=1e-12, atol=0.0)


# --------------------------------------------------------------------------- the column

def _panel_materials(translucency):
    return MaterialTable(("Panel", "Lamp"), [COLOR, [0, 0, 0]], [1, 1], [0, 0], [0, 0],
                         [[0, 0, 0], [2.0] * 3], (), [0, 0], [1.5, 1.5], translucency)


def test_column_defaults_and_npz_round_trip(tmp_path):
    t = MaterialTable.diffuse(["a", "b"], [[0.5] * 3] * 2)
    assert t.translucency.dtype == np.float32 and t.translucency.tolist() == [0.0, 0.0]
    desc = panel_scene(translucency=0.25)
    save_npz(desc, tmp_path / "s.npz")
    back = load_npz(tmp_path / "s.npz")
    np.testing.assert_array_equal(back.materials.translucency, np.float32([0.25, 0.0]))
    # a file written before the column existed loads as opaque
    with np.load(tmp_path / "s.npz") as z:
        data = {k: z[k] for k in z.files if k != "materials.translucency"}
    np.savez(tmp_path / "old.npz", **data)
    np.testing.assert_array_equal(load_npz(tmp_path / "old.npz").materials.translucency, 0.0)


def test_validation_clamps_with_a_warning_naming_the_material():
    from ercuts_core.validate import sanitize
    desc = replace(panel_scene(), materials=replace(_panel_materials([1.5, 0.0]),
                                                    names=("Velvet", "Lamp")))
    v = sanitize(desc)
    msgs = [i.message for i in v.issues if i.code == "translucency_out_of_range"]
    assert len(msgs) == 1 and "'Velvet'" in msgs[0] and "1.5" in msgs[0]
    assert v.desc.materials.translucency.tolist() == [1.0, 0.0, 0.0]     # + the fallback row
    desc = replace(desc, materials=replace(desc.materials, translucency=np.float32([np.nan, -0.5])))
    v = sanitize(desc)
    codes = sorted(i.code for i in v.issues)
    assert codes == ["nonfinite_material", "translucency_out_of_range"], codes
    assert any("'Velvet'" in i.message for i in v.issues if i.code == "nonfinite_material")
    assert v.desc.materials.translucency.tolist() == [0.0, 0.0, 0.0]


def test_program_output_translucency():
    """A program's ``translucency`` output drives the lobe per point (here a constant 0.75
    over a row constant of 0) through BuiltScene.bsdf and bsdf_max_value."""
    import json
    from ercuts_core.scene import BuiltScene
    from ercuts_core.validate import sanitize
    prog = json.dumps({"version": 1, "nodes": [], "outputs": {"translucency": 0.75}})
    desc = panel_scene(translucency=0.0)
    desc = replace(desc, materials=replace(desc.materials, programs=(prog, "")))
    scene = BuiltScene(sanitize(desc).desc)
    try:
        up = np.array([[0.0, 0.0, 1.0]])
        hit = scene.intersect(np.array([[0.1, 0.1, 1.0]]), np.array([[0.0, 0.0, -1.0]]))
        b = scene.bsdf(hit.mat, up, up, hit.p)
        np.testing.assert_allclose(b.kdt[0], 0.75 * np.array(COLOR), rtol=1e-6)
        np.testing.assert_allclose(scene.bsdf_max_value(hit.mat, hit.p)[0],
                                   np.array(COLOR) / np.pi, rtol=1e-6)
        assert not scene.has_delta and not scene.has_specular_or_glass
    finally:
        scene.close()


# --------------------------------------------------------------------------- end to end

W, H = 16, 12
LE = 2.0
LAMP_HALF = 30.0      # the emitter's half size [m], 1 m below the panel


def _quads(quads):
    pos, tris, mat, obj = [], [], [], []
    for i, (corners, m) in enumerate(quads):
        pos.append(np.array(corners, np.float64))
        tris.append(np.array([[0, 1, 2], [0, 2, 3]]) + 4 * i)
        mat += [m, m]
        obj += [i, i]
    return MeshTable(np.concatenate(pos), np.concatenate(tris), mat, obj)


def _camera():
    return CameraDesc(look_at((0, 0, 5), (0, 0, 0)), W, H, projection="ORTHO", ortho_scale=1.0)


def panel_scene(translucency=1.0) -> SceneDescription:
    """A translucent panel z = 0 (±3 m, colour C, no reflection) over an emitter z = −1
    (±30 m, radiance Le, black), seen from above by an orthographic camera; black world."""
    panel = [(-3, -3, 0), (3, -3, 0), (3, 3, 0), (-3, 3, 0)]
    a = LAMP_HALF
    lamp = [(-a, -a, -1), (a, -a, -1), (a, a, -1), (-a, a, -1)]
    return SceneDescription(_quads([(panel, 0), (lamp, 1)]), _panel_materials([translucency, 0.0]),
                            _camera(), object_names=("Panel", "Lamp"))


def view_factor(x, y, a=LAMP_HALF, h=1.0):
    """View factor from a point (x, y) facing the parallel square [−a, a]² at distance h:
    four rectangles with a corner under the point [Howell's catalogue, C-11]."""
    def corner(p, q):
        p, q = p / h, q / h
        return (p / np.sqrt(1 + p * p) * np.arctan(q / np.sqrt(1 + p * p))
                + q / np.sqrt(1 + q * q) * np.arctan(p / np.sqrt(1 + q * q))) / (2 * np.pi)
    return sum(corner(p, q) for p in (a - x, a + x) for q in (a - y, a + y))


@pytest.mark.parametrize("integrator", ["PATH", "BDPT", "ERCUTS"])
def test_panel_before_an_emitter_is_analytic(integrator):
    """Every pixel sees C·Le·F(x, y) (the panel transmits, reflects nothing; the emitter is
    black): the image mean per channel within 4.5 standard errors (pixels' spread)."""
    r = render(panel_scene(), RenderSettings(integrator=integrator, samples=64, rough_samples=4,
                                             direct_samples=64, max_depth=8, seed=5))
    img = r.image[..., :3].astype(np.float64)
    ys, xs = (np.arange(H) + 0.5) / H * 0.75 - 0.375, (np.arange(W) + 0.5) / W - 0.5
    F = view_factor(xs[None, :], ys[:, None])
    expect = np.array(COLOR)[None, None, :] * LE * F[..., None]
    res = (img - expect).reshape(-1, 3)
    se = res.std(axis=0, ddof=1) / np.sqrt(len(res))
    z = res.mean(axis=0) / np.maximum(se, 1e-12)
    print(integrator, "mean", img.reshape(-1, 3).mean(0), "expected", expect.reshape(-1, 3).mean(0),
          "z", z)
    assert np.all(np.abs(z) < 4.5), z
    assert F.min() > 0.97


def backlit_scene(translucency=0.6) -> SceneDescription:
    """A panel z = 0 (±3 m, colour C, translucency ``translucency`` over Lambert) above a
    white wall z = −1 (±3 m, 0.8); a 1 m² area light at z = −0.5 shines down on the wall only.
    All light the camera gets went wall → panel (through it) → camera: indirect."""
    panel = [(-3, -3, 0), (3, -3, 0), (3, 3, 0), (-3, 3, 0)]
    wall = [(-3, -3, -1), (3, -3, -1), (3, 3, -1), (-3, 3, -1)]
    mats = MaterialTable(("Panel", "Wall"), [COLOR, [0.8] * 3], [1, 1], [0, 0], [0, 0],
                         np.zeros((2, 3)), (), [0, 0], [1.5, 1.5], [translucency, 0.0])
    area = AreaLights([[0.3, -0.2, -0.5]], [[0.5, 0, 0]], [[0, 0.5, 0]], [[0, 0, -1.0]], [[20.0] * 3],
                      [0], [2])
    return SceneDescription(_quads([(panel, 0), (wall, 1)]), mats, _camera(), area_lights=area,
                            object_names=("Panel", "Wall", "Light"))


def _energies(integrator, k, **kw):
    out = []
    for i in range(k):
        r = render(backlit_scene(), RenderSettings(integrator=integrator, seed=200 + i, max_depth=12, **kw))
        assert np.isfinite(r.image).all()
        out.append(float(r.image[..., :3].astype(np.float64).mean()))
    return np.array(out)


PATH_SPP = 256
BDPT_SPP = 64
ERCUTS_KW = dict(rough_samples=8, direct_samples=16)


def _se(a):
    return a.std(ddof=1) / np.sqrt(len(a))


def test_backlit_panel_energy_agrees_across_integrators():
    k = 4
    path = _energies("PATH", k, samples=PATH_SPP)
    bdpt = _energies("BDPT", k, samples=BDPT_SPP)
    ercuts = _energies("ERCUTS", k, **ERCUTS_KW)
    print("PATH", path.mean(), _se(path), "BDPT", bdpt.mean(), _se(bdpt), "ERCUTS", ercuts.mean(),
          _se(ercuts), "ERCUTS/PATH", ercuts.mean() / path.mean())
    assert path.mean() > 0.05
    assert abs(bdpt.mean() - path.mean()) < 4 * np.hypot(_se(path), _se(bdpt))
    s_pe = np.hypot(_se(path), _se(ercuts))
    assert abs(ercuts.mean() / path.mean() - 1) < 0.02 + 4 * s_pe / path.mean()


def test_backlit_panel_fails_when_the_panel_is_treated_as_opaque(monkeypatch):
    """The comparisons above can fail: BDPT dropping connections through the panel
    (``reflect_only`` from the glass lobe alone, as before) and ERCUTS's gather taking VPL
    light from the panel's own side only (not ``transmissive``) lose most of the image."""
    from ercuts_core.integrators.ercuts import gather
    path = _energies("PATH", 1, samples=PATH_SPP)[0]
    monkeypatch.setattr(Bsdf, "reflect_only", property(lambda self: self.p_tr <= 0.0))
    bdpt = _energies("BDPT", 1, samples=BDPT_SPP)[0]
    monkeypatch.undo()
    orig = gather.ShadingPoints

    def opaque(*args, transmissive=None, **kw):
        return orig(*args, transmissive=None, **kw)
    monkeypatch.setattr(gather, "ShadingPoints", opaque)
    ercuts = _energies("ERCUTS", 1, **ERCUTS_KW)[0]
    print("PATH", path, "BDPT opaque", bdpt / path, "ERCUTS opaque", ercuts / path)
    assert bdpt < 0.9 * path and ercuts < 0.5 * path
