"""Depth of field (thin lens) through every integrator.

* BDPT's light-tracing strategy connects to sampled lens points (t = 1 splats): it agrees
  with PATH, whose camera rays start on the lens, pixel by pixel.
* ERCUTS: seed paths keep their lens point (x0) and raster consistent, the lens and caustic
  perturbations keep the lens point and still leave the chains' target invariant, and the
  image energy (its E1 traces VPL light to sampled lens points) agrees with BDPT's.
"""
from __future__ import annotations

import dataclasses
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))
from test_bdpt import _assert_agree, _renders  # noqa: E402
from test_soft_lights import soft_box  # noqa: E402

from ercuts_core import RenderSettings, render  # noqa: E402
from ercuts_core.sampling import luminance  # noqa: E402
from ercuts_core.scene import BuiltScene  # noqa: E402
from ercuts_core.scenes import cornell_box  # noqa: E402
from ercuts_core.validate import sanitize  # noqa: E402


def with_lens(desc, radius=0.12, focus=3.9, blades=6):
    """The scene seen through a thin lens (the front of the Cornell box's tall box is 3.9 m away)."""
    cam = dataclasses.replace(desc.camera, aperture_radius=radius, focus_distance=focus,
                              aperture_blades=blades, aperture_rotation=0.2)
    return desc.replace(camera=cam)


def test_bdpt_agrees_with_path_through_a_lens():
    """Light tracing (t = 1, random lens point per connection) against camera rays."""
    desc = with_lens(cornell_box(24, 18, "mesh"))
    path = _renders(desc, "PATH", 10, 32, seed0=1000)
    bdpt = _renders(desc, "BDPT", 10, 16, seed0=2000)
    _assert_agree(path, bdpt)


def test_the_lens_blurs_what_is_out_of_focus():
    """DOF is applied at all: the first-hit albedo's edges (red, green and white walls and
    boxes; nearly noise-free) lose most of their gradient energy when focused far in front."""
    def albedo(desc):
        res = render(desc, RenderSettings(integrator="PATH", samples=64, seed=1, max_depth=1))
        return res.aovs["albedo"].astype(np.float64)

    def energy(a):
        return (np.diff(a, axis=0) ** 2).sum() + (np.diff(a, axis=1) ** 2).sum()

    pin = albedo(cornell_box(32, 24, "mesh"))
    sharp = albedo(with_lens(cornell_box(32, 24, "mesh"), radius=0.005))
    blurred = albedo(with_lens(cornell_box(32, 24, "mesh"), radius=0.3, focus=1.0))
    assert abs(energy(sharp) / energy(pin) - 1) < 0.1
    assert energy(blurred) < 0.5 * energy(pin)


def test_seed_paths_keep_their_lens_point():
    """BDPT seeds (camera-side and t = 1 rows): x0 on the aperture, and x1 projects through
    x0 to the stored raster position."""
    from ercuts_core.integrators.ercuts.paths import contribution, edge_visible
    from ercuts_core.integrators.ercuts.seeding import seed_paths

    scene = BuiltScene(sanitize(with_lens(cornell_box(16, 12, "mesh"))).desc)
    paths, e = seed_paths(scene, RenderSettings(max_depth=4), np.random.default_rng(0))
    cam = scene.camera
    local = (paths.p[:, 0] - cam.position) @ cam.rotation
    assert np.abs(local[:, 2]).max() < 1e-9 and (np.hypot(local[:, 0], local[:, 1]) <= 0.12 + 1e-9).all()
    assert np.unique(np.round(local[:, :2], 6), axis=0).shape[0] > len(paths) // 2
    raster, inside = cam.raster_of(paths.p[:, 1], paths.p[:, 0])
    assert inside.all() and np.abs(raster - paths.raster).max() < 1e-4
    assert (contribution(scene, paths).max(axis=1) > 0).all()
    assert edge_visible(scene, paths, np.ones(len(paths), np.int64)).all()
    scene.close()


@pytest.mark.parametrize("mutator", [0, 1])
def test_perturbed_paths_are_camera_rays_from_their_lens_point(mutator):
    """Every valid lens / caustic proposal keeps x0 (the lens point), and its x1 is what the
    camera ray from x0 through the new raster position hits."""
    from ercuts_core.integrators.ercuts.initialization import seeds_from_path_tracer
    from ercuts_core.integrators.ercuts.mutations import MUTATORS, MutationContext

    scene = BuiltScene(sanitize(with_lens(cornell_box(24, 18, "area"), radius=0.2, focus=2.0)).desc)
    x, _ = seeds_from_path_tracer(scene, 3, np.random.default_rng(3))
    prop = MUTATORS[mutator](MutationContext(scene, 4), x, np.random.default_rng(4))
    y = prop.paths.take(np.flatnonzero(prop.valid))
    assert len(y) > len(x) // 4
    np.testing.assert_array_equal(y.p[:, 0], x.p[prop.valid, 0])
    o, d = scene.camera.rays_from(y.raster, y.p[:, 0])
    hit = scene.intersect(o, d)
    assert hit.valid.all()
    np.testing.assert_allclose(hit.p, y.p[:, 1], atol=1e-5)
    scene.close()


@pytest.mark.slow
@pytest.mark.parametrize("mutator", [0, 1])
def test_lens_and_caustic_perturbations_preserve_the_target_through_a_lens(mutator):
    """test_er_sampling's invariance test (chains started ∝ f stay ∝ f; pixel-block chi²)
    with a lens: the perturbations keep the path's lens point and their ratios hold."""
    import test_er_sampling as er

    scene = BuiltScene(sanitize(with_lens(cornell_box(er.W, er.H, light="area"), radius=0.2,
                                          focus=2.0)).desc)
    seeds, e = er.pool(scene, 1, 120)
    ref, e_ref = er.pool(scene, 2, 120)
    rng = np.random.default_rng(30 + mutator)
    end = er.final_states(scene, er.resample(seeds, e, 3000, rng), mutator, 12, rng)
    counts = np.bincount(er.bins(end)[0], minlength=9)
    p = er.chi2_pvalue(counts, er.expected(ref, e_ref, 0))
    assert p > er.SIG, (counts, er.expected(ref, e_ref, 0) * counts.sum(), p)
    scene.close()


@pytest.mark.slow
def test_ercuts_energy_agrees_with_bdpt_through_a_lens_with_soft_lights():
    """ERCUTS (VPLs normalised by Ê1, which light-traces to lens points; soft point and spot
    lights by next-event estimation) keeps BDPT's image energy within 3 %."""
    desc = with_lens(soft_box(True, 32, 24), radius=0.08, focus=1.0, blades=0)
    fast = dict(samples=8, chain_length=40, chains_per_pixel=0.5)
    ercuts = render(desc, RenderSettings(integrator="ERCUTS", seed=1, **fast))
    bdpt = [render(desc, RenderSettings(integrator="BDPT", samples=16, seed=s)).image for s in range(3)]
    e_b = np.mean([luminance(b[..., :3]).mean() for b in bdpt])
    e_e = luminance(ercuts.image[..., :3]).mean()
    assert abs(e_e / e_b - 1) < 0.03, (e_e, e_b)
    assert abs(ercuts.stats["vpl_energy_ratio"] - 1) < 0.05
