"""Delta lobes of ercuts_core.bsdf: the perfect mirror and the smooth glass lobe (issue 15).

What pbrt-v4's and Mitsuba 3's tests check for specular BSDFs: the sampled direction (mirror
reflection, Snell's law), the weight = lobe factor / event probability, eval = pdf = 0 (no
connection can reach a delta lobe), energy conservation (a clear glass interface reflects and
transmits everything: E[weight] = 1 in importance transport), total internal reflection, the
non-symmetric η² factor of radiance transport, finiteness at grazing angles, and the
one-sample mixture of delta and continuous lobes (Principled transmission 0.5).
"""
from __future__ import annotations

import numpy as np
import pytest

from ercuts_core.bsdf import DELTA_ALPHA, Bsdf, fresnel_dielectric, schlick_fresnel
from ercuts_core.sampling import coordinate_system

N = np.array([0.2, -0.4, 0.9]) / np.linalg.norm([0.2, -0.4, 0.9])


def lanes(n, color=(1.0, 1.0, 1.0), rough=0.0, metal=0.0, spec=0.5, trans=1.0, ior=1.5, ng=N):
    return Bsdf.from_params(np.tile(color, (n, 1)), np.full(n, rough), np.full(n, metal),
                            np.full(n, spec), np.tile(ng, (n, 1)), np.tile(ng, (n, 1)),
                            transmission=np.full(n, trans), ior=np.full(n, ior))


def direction(cos_t, phi, n=N):
    t, b = coordinate_system(n[None, :])
    s = np.sqrt(max(0.0, 1.0 - cos_t * cos_t))
    return (s * np.cos(phi) * t + s * np.sin(phi) * b + cos_t * n[None, :])[0]


def test_delta_threshold_is_cycles_singular_roughness():
    # Cycles treats alpha_x·alpha_y ≤ 1e-7 as singular: roughness ≤ 0.01778
    assert lanes(1, rough=0.0177, metal=1.0, trans=0.0).delta[0]
    assert not lanes(1, rough=0.02, metal=1.0, trans=0.0).delta[0]
    assert DELTA_ALPHA == pytest.approx(1e-7 ** 0.5)


def test_mirror_reflects_with_schlick_weight_and_no_eval():
    n = 64
    b = lanes(n, color=(0.9, 0.6, 0.3), metal=1.0, trans=0.0)
    assert b.is_delta.all() and b.has_delta
    wo = np.tile(direction(0.6, 1.0), (n, 1))
    s = b.sample(wo, np.random.default_rng(1).random((n, 3)))
    refl = 2.0 * 0.6 * N - wo[0]
    assert s.valid.all() and s.is_delta.all()
    np.testing.assert_allclose(s.wi, np.tile(refl, (n, 1)), atol=1e-12)
    F = schlick_fresnel(np.array([0.6]), np.array([[0.9, 0.6, 0.3]]), np.ones((1, 3)))
    np.testing.assert_allclose(s.weight, np.tile(F, (n, 1)), rtol=1e-12)
    np.testing.assert_allclose(s.pdf, 1.0)
    # no direction has a value or a density: light sampling and connections see nothing
    assert not b.eval(wo, s.wi).any() and not b.pdf(wo, s.wi).any()


def test_fresnel_dielectric_limits():
    F, cos_t = fresnel_dielectric(np.array([1.0, 0.0, 0.3]), np.array([1.5, 1.5, 1 / 1.5]))
    assert F[0] == pytest.approx(0.04)              # ((η − 1)/(η + 1))² at normal incidence
    assert F[1] == 1.0                              # grazing
    assert F[2] == 1.0 and cos_t[2] == 0.0          # sin θ_t = 0.954·1.5 > 1: total internal reflection


def _glass_samples(cos_o, inside=False, n=200_000, adjoint=True, seed=3):
    ng = -N if inside else N                       # wo on the far side of ng: leaving the glass
    b = lanes(n, ng=ng)
    wo = np.tile(direction(cos_o, 0.4), (n, 1))
    return b, wo, b.sample(wo, np.random.default_rng(seed).random((n, 3)), adjoint=adjoint)


@pytest.mark.parametrize("cos_o", [1.0, 0.7, 0.2, 0.01])
def test_glass_conserves_energy_and_follows_snell(cos_o):
    b, wo, s = _glass_samples(cos_o)
    assert s.valid.all() and s.is_delta.all()
    Fr, _ = fresnel_dielectric(np.array([cos_o]), np.array([1.5]))
    refl = np.einsum("ij,j->i", s.wi, N) > 0
    # importance transport: weight 1 for both events, reflections with probability F_r
    np.testing.assert_allclose(s.weight, 1.0, rtol=1e-12)
    se = np.sqrt(Fr[0] * (1 - Fr[0]) / len(refl))
    assert abs(refl.mean() - Fr[0]) < 5 * se + 1e-12
    # Snell: sin θ_t = sin θ_o / 1.5, in the plane of wo and n, on the other side
    t = s.wi[~refl]
    sin_o = np.sqrt(1 - cos_o ** 2)
    # sin θ_t as the length of t's tangential part (|t × n|): sqrt(1 − cos²) near normal
    # incidence turns a rounding of cos θ_t (1 − 2⁻⁵²) into 2·10⁻⁸ on some machines' BLAS
    np.testing.assert_allclose(np.linalg.norm(np.cross(t, N), axis=1), sin_o / 1.5, atol=1e-9)
    assert np.all(t @ N < 0)
    np.testing.assert_allclose(np.cross(wo[0], N) @ t.T, 0.0, atol=1e-9)


def test_total_internal_reflection_from_inside():
    # leaving the glass at 60°: sin = 0.87 > 1/1.5, every sample reflects with weight 1
    b, wo, s = _glass_samples(0.5, inside=True, n=1000)
    assert s.valid.all() and (np.einsum("ij,j->i", s.wi, N) > 0).all()   # stays on wo's side
    np.testing.assert_allclose(s.weight, 1.0)


def test_radiance_transport_carries_one_over_eta_squared_and_a_slab_cancels_it():
    b, wo, s = _glass_samples(0.8, adjoint=False, n=4000)
    refl = np.einsum("ij,j->i", s.wi, N) > 0
    np.testing.assert_allclose(s.weight[~refl], 1 / 1.5 ** 2, rtol=1e-12)
    np.testing.assert_allclose(s.weight[refl], 1.0, rtol=1e-12)
    # back out through a parallel face: the refracted ray seen from inside, η_rel = 1/1.5
    t = s.wi[~refl][:1]
    inside = lanes(4000, ng=-N)
    s2 = inside.sample(np.tile(-t[0], (4000, 1)), np.random.default_rng(4).random((4000, 3)))
    out = np.einsum("ij,j->i", s2.wi, -N) > 0         # through the back face (outward normal −N)
    assert 0 < out.mean() < 1
    np.testing.assert_allclose(s2.weight[out], 1.5 ** 2, rtol=1e-12)
    # the two factors cancel: radiance through a slab is scaled by transmittances only
    np.testing.assert_allclose(s.weight[~refl][0] * s2.weight[out][0], 1.0, rtol=1e-12)
    np.testing.assert_allclose(s2.wi[out][0], -wo[0], atol=1e-9)   # the ray leaves parallel


def test_glass_is_finite_at_grazing_and_degenerate_inputs():
    n = 6
    b = lanes(n)
    wo = np.array([N, -N, direction(1e-14, 0.3), np.zeros(3), direction(0.5, 1.0), [np.nan] * 3])
    with np.errstate(all="raise", under="ignore"):
        s = b.sample(wo, np.full((n, 3), 0.5))
    for a in (s.wi[:5], s.weight, s.pdf, s.f):
        assert np.isfinite(np.nan_to_num(a, nan=0.0)).all()
    assert np.isfinite(s.weight).all() and np.isfinite(s.pdf).all()
    assert not s.valid[3]


def test_principled_half_transmission_mixture_is_unbiased():
    # transmission 0.5, roughness 0: diffuse + delta F0_d coat (weight 0.5) and smooth glass
    # (0.5). E[weight] in importance transport = ∫ f cos + delta parts, estimated two ways.
    n = 400_000
    color = (0.6, 0.7, 0.8)
    b = lanes(n, color=color, trans=0.5)
    assert not b.is_delta.any() and b.has_delta
    wo = np.tile(direction(0.7, 0.2), (n, 1))
    s = b.sample(wo, np.random.default_rng(5).random((n, 3)), adjoint=True)
    assert s.valid.mean() > 0.99
    Fr = fresnel_dielectric(np.array([0.7]), np.array([1.5]))[0][0]
    F_coat = schlick_fresnel(np.array([0.7]), np.full((1, 3), 0.04), np.full((1, 3), 0.04))[0]
    kd = 0.5 * 0.96 * np.array(color)
    expected = kd + 0.5 * F_coat + 0.5 * (Fr + (1 - Fr) * np.array(color))
    mean = s.weight.mean(axis=0)
    se = s.weight.std(axis=0) / np.sqrt(n)
    assert (np.abs(mean - expected) < 5 * se).all(), (mean, expected, se)
    # the continuous part alone: its samples' pdf equals pdf() (the delta events are excluded)
    cont = ~s.is_delta & s.valid
    np.testing.assert_allclose(s.pdf[cont], b.subset(cont).pdf(wo[cont], s.wi[cont]), rtol=1e-10)


def test_material_table_columns_default_to_opaque():
    from ercuts_core.description import MaterialTable
    t = MaterialTable.diffuse(["a", "b"], [[0.5] * 3] * 2)
    np.testing.assert_array_equal(t.transmission, 0.0)
    np.testing.assert_array_equal(t.ior, np.float32(1.5))
    g = Bsdf.from_table(MaterialTable(("g",), [[1, 1, 1]], [0.0], [0.0], [0.5], [[0, 0, 0]],
                                      (), [1.0], [1.33]), [0], [N], [N])
    assert g.is_delta[0] and g.eta[0] == pytest.approx(1.33)
