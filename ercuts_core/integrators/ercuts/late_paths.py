"""ERCUTS's direct-light passes when its gather follows the camera through mirrors and glass:
the paths with a late event by BDPT, the others by path tracing.

With the gather following the camera through mirrors and glass (:func:`.vpl.follow_specular`,
algorithm.md §G.3), the direct-light passes render the paths the VPLs cannot carry
(``paths='direct_and_late_delta'``, :class:`~ercuts_core.integrators.path.PathIntegrator`): light
seen directly, or through the prefix of mirrors and glass the camera looks through, with at most
one scattering vertex after it; and the paths with a *late* event — a delta event after that
prefix, or a mirror or glass vertex right after its first surface: caustics, a lamp seen behind
glass, light a mirror throws onto the floor. Path tracing finds a late path through a perfect
mirror or smooth glass only when a BSDF sample, after the specular chain, happens to hit the
emitter (no light sample reaches through a delta vertex). In the mirror-and-glass room, whose
lamp a mirror shows to the floor and the walls, that made the direct passes most of ERCUTS's
error: one untimed iteration with 63 direct passes had a relMSE of 0.032, the 60 s render with
18 passes over two iterations 0.11–0.15 (fireflies 5–10× the reference all over the floor).

BDPT samples such paths from the light side too (light tracing, t = 1: lamp → mirror → floor →
camera) and weights every strategy by MIS [Veach 1997 ch. 10]; restricted to the late set
(``BDPTIntegrator(paths='late_delta')``: the same path classes, the MIS weights of all strategies,
the connections of other paths not made) it is an unbiased estimator of exactly that part. So
each direct pass here is a path-traced pass of the rest (``paths='direct_through_prefix'``; the
two sets are disjoint and their union is the whole, tests/test_follow_specular.py) plus a BDPT
pass of the late paths over the same film, which adds light but no coverage
(:attr:`BDPTIntegrator.light_only`). Measured at 60 s, 160×120 (relMSE, seeds 0 / 1): the
mirror room 0.154 / 0.167 → 0.114 / 0.112; Veach's room, whose late light (the ceiling seen
through a glass egg) path tracing samples as well, 3.3 / 3.7e-3 → 3.4 / 3.4e-3 (four seeds: 3.27
against 3.50e-3 on average, within their spread). A BDPT pass of the late set costs ≈ 2×
a path-traced pass there (0.26 s against 0.12 s with four light samples; all connections made:
0.70 s). Only scenes with delta lobes split: after a rough metal or rough glass every vertex
takes light samples.
"""
from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from ...film import Film
from ...qmc import PassSequence
from ...scene import BuiltScene
from ...settings import RenderSettings
from ..base import Integrator
from ..bdpt import BDPTIntegrator
from ..path import PathIntegrator

#: The late paths by BDPT (False: the ablation, path tracing all of 'direct_and_late_delta').
LATE_BY_BDPT = True


class SplitPasses(Integrator):
    """One direct-light pass: ``PathIntegrator(paths='direct_through_prefix')`` and
    ``BDPTIntegrator(paths='late_delta')`` over the same film (module docstring). The light
    samples at the first hit (``light_samples``, :meth:`set_light_samples`, ``light_spread``)
    are the path tracer's."""

    def __init__(self, scene: BuiltScene, settings: RenderSettings, light_samples: int = 1):
        super().__init__(scene, settings)
        self.direct = PathIntegrator(scene, settings, paths="direct_through_prefix", light_samples=light_samples)
        self.late = BDPTIntegrator(scene, settings, paths="late_delta")

    @property
    def light_samples(self) -> int:
        return self.direct.light_samples

    def set_light_samples(self, k: int, passes_done: int) -> None:
        self.direct.set_light_samples(k, passes_done)

    @property
    def light_spread(self) -> NDArray | None:
        return self.direct.light_spread

    @light_spread.setter
    def light_spread(self, value: NDArray | None) -> None:
        self.direct.light_spread = value

    def render_batch(self, film: Film, pix: NDArray, rng: np.random.Generator,
                     sequence: PassSequence | None = None) -> None:
        """One sample of each set per pixel ``pix`` (N,); the pass's quasi-random point is the
        path tracer's (the BDPT samples draw from ``rng``: the two stay uncorrelated)."""
        self.direct.render_batch(film, pix, rng, sequence)
        self.late.render_batch(film, pix, rng)


def direct_passes(scene: BuiltScene, settings: RenderSettings, paths: str, light_samples: int) -> Integrator:
    """The integrator of ERCUTS's direct-light passes of the path set ``paths``
    (:meth:`~.integrator.ErcutsIntegrator._direct_light`): :class:`SplitPasses` for
    'direct_and_late_delta' in a scene with delta lobes (``BuiltScene.has_delta``: perfect
    mirrors, smooth glass) and :data:`LATE_BY_BDPT`, else the path tracer — without delta lobes
    every vertex of a late path (one after a rough metal or rough glass) takes light samples."""
    if paths == "direct_and_late_delta" and LATE_BY_BDPT and scene.has_delta:
        return SplitPasses(scene, settings, light_samples)
    return PathIntegrator(scene, settings, paths=paths, light_samples=light_samples)
