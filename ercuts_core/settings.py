"""Render settings: one frozen dataclass holding every core parameter and its default.

The add-on's ``scene.ercuts`` PropertyGroup mirrors these fields one-to-one (same names,
defaults and ranges; a test checks it). :meth:`RenderSettings.from_dict` rejects unknown
keys, like pbrt-v4's ``ReportUnused``.
"""
from __future__ import annotations

import dataclasses
import os
import re
from dataclasses import dataclass, fields

INTEGRATORS = ("ERCUTS", "BDPT", "PATH")
GATHERS = ("LIGHTCUTS", "STOCHASTIC", "BRUTE_FORCE")
SEEDINGS = ("BDPT", "PATH")
DIRECT_LIGHTS = ("NEE", "VPL")
LIGHTCUT_ERRORS = ("NODE", "TOTAL", "LITERAL")
TREE_PAIRINGS = ("PLOC", "GREEDY")


#: ``ERCUTS_QUICK=1`` (README: smoke runs of the documented commands) caps every render's
#: time limit at this many seconds (:func:`quick_time_limit`).
QUICK_TIME_LIMIT = 3.0


def quick() -> bool:
    """``ERCUTS_QUICK`` is set to something other than empty or ``0``."""
    return os.environ.get("ERCUTS_QUICK", "0") not in ("", "0")


def quick_time_limit(limit: float) -> float:
    """``limit`` (seconds, 0 = none), capped at :data:`QUICK_TIME_LIMIT` under ``ERCUTS_QUICK``
    (the add-on and the command line apply it to every render they start)."""
    if not quick():
        return limit
    return min(limit, QUICK_TIME_LIMIT) if limit > 0 else QUICK_TIME_LIMIT


#: ``RenderSettings.cluster`` values: '' (this process), 'local', 'auto', 'ray://host:port'
#: (Ray client) or 'host:port' (a head node's GCS address).
CLUSTER_ADDRESS = re.compile(r"(|local|auto|(ray://)?[A-Za-z0-9_.\-\[\]:]+:[0-9]{1,5})")


def valid_cluster_address(address: str) -> bool:
    """``address`` is a value :attr:`RenderSettings.cluster` accepts (:data:`CLUSTER_ADDRESS`)."""
    return isinstance(address, str) and CLUSTER_ADDRESS.fullmatch(address) is not None


#: Renders of at least this many pixels (1280×720 and up) count as high resolution for the
#: automatic settings: the gather's spacing 2 (``gather_spacing`` = 0) and one shading point
#: per pixel (``shading_samples`` = 0); below it, every point gathered and four per pixel.
HIGH_RESOLUTION_PIXELS = 800_000
#: ``shading_samples`` = 0: the shading points per pixel for renders of fewer than this many
#: pixels (largest first); from the largest on, one (:meth:`RenderSettings.shading_points`).
AUTO_SHADING_SAMPLES = ((HIGH_RESOLUTION_PIXELS, 4),)


#: BDPT seed samples per iteration up to which ``seed_samples`` > 1 may add samples
#: (:meth:`RenderSettings.seed_rate`): seeds cost ≈ 0.33 s per 19 200 samples at 160×120
#: (directly lit scene: 14.4 → 15.4 s an iteration for 1 → 4 per pixel; S-corridor 42.9 →
#: 44.1 s for 1 → 4, 60 s for 16), so the budget keeps them under ≈ 2.5 s an iteration
#: (160×120 takes 4 per pixel, 320×240 1.7); renders from 640×480 up, whose chains already
#: start from ≥ 3·10⁵ seed samples, keep what one per pixel gives.
SEED_SAMPLE_BUDGET = 1 << 17


@dataclass(frozen=True)
class RenderSettings:
    """Core render settings.

    Attributes:
        integrator: 'ERCUTS' (the paper: BDPT → ER chains → VPLs → light tree →
            lightcuts), 'BDPT' (bidirectional path tracing with MIS; also the "BDPT only"
            ablation) or 'PATH' (the reference path tracer with next-event estimation).
        samples: PATH and BDPT samples per pixel. The default is Cycles' (4096): with a
            ``time_limit`` the limit is what stops the render, as in Cycles (issue 13).
        rough_samples: ERCUTS: samples per pixel of each iteration's rough BDPT image
            (step 1), which only measures P, seeds the chains and previews: at most 2^19
            camera samples per iteration in all: beyond, the rough image has a lower
            resolution (``initialization.rough_factor``). It stops earlier once P is known
            to 1 % (relative standard error over at least 4 passes, ``stats['P_relative_error']``).
        seed: random seed; the same seed and settings give the same image.
        max_depth: maximum number of bounces (path segments − 1); 1 = direct light only.
            The default 64 keeps the light of deep interiors (8 lost up to 64 % of it in an
            S-shaped corridor); Russian roulette after ``rr_depth`` bounces ends the paths
            that carry little, so the cost grows far less than the depth (issue 13).
        rr_depth: bounces before Russian roulette starts.
        time_limit: seconds for the whole render (0 = none); the image rendered so far
            is returned when it runs out.
        film_transparent: alpha = coverage instead of 1.
        batch_rays: target rays per wavefront batch (memory vs. per-call overhead).
        threads: embreex threads per batch (0 = all cores).
        max_error: lightcut error threshold relative to the estimate (Weber's law, 2 %).
        iterations: ERCUTS iterations, each a complete, independent Ercuts estimate (its own
            rough BDPT, chains, VPLs, tree and gather; seed and VPL clamp from the iteration
            index), averaged (:mod:`~ercuts_core.integrators.ercuts.progressive`); 0 = as many
            as ``time_limit`` allows (one without a time limit).
        iteration_start: index of the first iteration rendered (iterations
            ``iteration_start`` … ``iteration_start + iterations − 1``), so that a frame's
            iterations can be split over several renders and averaged.
        chains_per_pixel: average number of ER chains started per pixel (c).
        seed_samples: BDPT seed paths per pixel the chains start from (paper §3.2: one; the
            share of the pixels that seed when ``max_chains`` binds scales with it too). The
            chains only redistribute their seeds' energy locally, so the seeds' noise is the
            VPL image's coarse noise, which more chains do not lower (README, "More seeds,
            not more chains": 4 seeds per pixel took the S-corridor's and door's relMSE at
            60 s down by a third or more; 8 made the directly lit scene worse). The extra
            samples follow a budget (:data:`SEED_SAMPLE_BUDGET`, :meth:`seed_rate`).
        max_chains: ER chains of ``chain_length`` steps per iteration at most (the default
            leaves renders up to 256×256 at c = 0.25 unchanged); beyond it the chains' mutation
            steps, VPLs and memory follow the budget max_chains × chain_length instead of the
            pixel count (issue 17): the chains get shorter, down to ``min_chain_length``, and
            more numerous (:meth:`chain_plan`), and iterations add more.
        chain_length: mutation steps per chain (N); every step deposits P/n.
        min_chain_length: the shortest chains the step budget of ``max_chains`` is spread
            over (shorter, more independent chains: a VPL set with less correlated error;
            at 1280×720 on the door scene in one 300 s iteration, relMSE 0.0048 with 16 k
            chains of 100 steps, 0.0029 with 49 k of 33, 0.0026 with 82 k of 20).
        lens_perturbation, caustic_perturbation, multichain_perturbation (inactive: it needs
        perfectly specular lobes, which the core does not have yet; hidden in the UI),
        bidirectional_mutation: Veach's mutations used by the chains.
        max_cut_size: largest lightcut per shading point.
        clamp: VPL geometry clamp as a minimum distance, a fraction of the scene's bounding
            diagonal (cosθ/d² ≤ 1/(clamp·diagonal)²); 0 = off. The removed energy is reported.
        clamp_compensation: add back the light the clamp removes by Kollig and Keller's
            (2004) bias compensation — short BSDF rays from every shading point, the clamped
            estimate where they land (:mod:`~ercuts_core.integrators.ercuts.bias_compensation`)
            — and normalise the VPLs by their unclamped image energy; with ``direct_light=
            'NEE'`` only. Off: edges and corners lose the short-range light (the ablation).
        stochastic_cut_size: nodes per shading point of the 'STOCHASTIC' gather.
        stochastic_passes: passes of the 'STOCHASTIC' gather per iteration (each with new VPL
            draws), averaged: its per-pixel noise falls with them while the VPL set is shared;
            under a time limit fewer when the iteration's time runs out, and the last
            iteration fills the time left with more.
        stochastic_cut_sharing: shading points (neighbours in a pixel row) that share one
            stochastic cut, refined at the first of them (1 = every point its own cut; the
            default 4 made 6.4 gather passes instead of 2.4 in 120 s at 640×480 on the
            S-corridor, box-filtered relMSE 0.021 instead of 0.025); a
            point whose normal, plane or material differs keeps its own (edges). Each point
            still draws its own VPLs, so the estimate stays unbiased (module
            :mod:`~ercuts_core.integrators.ercuts.stochastic_lightcuts`).
        gather_spacing: the gather runs at one pixel in k×k (k = ``gather_spacing``; the
            grid shifts per iteration) and at every point that cannot be interpolated (edges,
            glossy or transmissive surfaces, what mirrors show); the other points interpolate
            their anchors' light where the G-buffer is smooth, scaled by the ratio of the
            reflectances (:mod:`~ercuts_core.integrators.ercuts.interpolation`). 1 = every
            point gathered; 0 (default) = automatic: 2 from 800 000 pixels (1280×720 and up).
        gather: 'STOCHASTIC' (default; stochastic lightcuts, Yuksel 2019: a cut of
            ``stochastic_cut_size`` nodes, each evaluated with one VPL drawn per shading point;
            unbiased for the VPLs, no error bound — its error is noise that the passes and
            iterations average: :mod:`~ercuts_core.integrators.ercuts.stochastic_lightcuts`;
            5.8× lower box-filtered error than 'LIGHTCUTS' on the S-corridor at 640×480 in
            120 s), 'LIGHTCUTS' (the light tree, the paper's bounded cuts, with the
            ``lightcut_error`` rule) or
            'BRUTE_FORCE' (every VPL at every shading point: the ablation that shows the
            tree's role).
        lightcut_error: the lightcut stopping rule (:func:`~ercuts_core.integrators.ercuts.
            lightcuts.lightcut`): 'NODE' refines while some cut node's error bound exceeds
            ``max_error`` of the estimate (Walter et al. 2005's practice; an ablation);
            'TOTAL' (default) bounds the *sum* of the nodes' bounds by ``max_error`` of the
            estimate (the paper's eq. (5)); 'LITERAL' the paper's text |L̄ − L| < ε·L per
            node (an ablation, not a bound).
        tree_pairing: how the light tree pairs clusters level by level: 'PLOC' (mutual-best
            rounds until half the clusters are paired) or 'GREEDY' (every mutual-best round
            to the end); an ablation (:mod:`~ercuts_core.integrators.ercuts.light_tree`).
        seeding: 'BDPT' (paper: seed chains from bidirectional paths) or 'PATH'.
        direct_light: how ERCUTS renders light that reaches the camera after one
            scattering: 'NEE' (default) with ``samples`` anti-aliased passes of next-event
            estimation + MIS from every light, the chains and VPLs carrying only indirect
            light; 'VPL' (the paper: chain paths whose x2 lies on an area light or emissive
            mesh become VPLs on the light, gathered with the rest).
        direct_samples: samples per pixel of ERCUTS's direct light passes
            (``direct_light='NEE'``).
        shading_samples: shading points (camera rays) per pixel for the VPL gather; the
            gather visits each pixel's first point and the others where they leave its
            surface (edges), the rest take its light (edge-adaptive anti-aliasing,
            :mod:`~ercuts_core.integrators.ercuts.interpolation`). 0 (default) = automatic:
            :data:`AUTO_SHADING_SAMPLES` (4 below 800 000 pixels, 1 from 1280×720 up, where
            ``gather_spacing`` 2 already shares the gather and 4 points would need 3 GB).
        e1_samples: shading points per VPL for its intensity normalisation (P*).
        normalize_to_p: ablation: scale the VPL image so its energy equals the rough BDPT's
            P (the behaviour before issue 13; it hid the VPL normalisation's bias). Off by
            default: the VPL image keeps the energy its per-VPL normalisation gives, and
            ``vpl_energy_ratio`` reports it against P.
        memory_budget_mb: memory the render may allocate, in MiB (0 = no limit); batch
            sizes are derived from it and a render whose estimate exceeds it even with the
            smallest batches is refused before allocating (:mod:`ercuts_core.memory`).
        cluster: where :func:`ercuts_core.cluster.render` (the command line's ``--cluster``,
            the add-on's final renders) runs the render's iterations as Ray tasks: '' = in
            this process (:func:`ercuts_core.render` always renders here), 'local' = a Ray
            cluster started on this machine for the render, 'auto' = the running cluster this
            machine belongs to, 'ray://host:port' (Ray client) or 'host:port' (the head's GCS).
            Needs the optional ``ray`` package (the ``cluster`` extra); the image does not
            depend on it (:mod:`ercuts_core.cluster`).
    """

    integrator: str = "ERCUTS"
    samples: int = 4096
    rough_samples: int = 16
    seed: int = 0
    max_depth: int = 64
    rr_depth: int = 3
    time_limit: float = 0.0
    film_transparent: bool = False
    batch_rays: int = 1 << 17
    threads: int = 0
    max_error: float = 0.02
    iterations: int = 0
    iteration_start: int = 0
    chains_per_pixel: float = 0.25
    seed_samples: int = 4
    max_chains: int = 16384
    chain_length: int = 100
    min_chain_length: int = 20
    lens_perturbation: bool = True
    caustic_perturbation: bool = True
    multichain_perturbation: bool = True
    bidirectional_mutation: bool = True
    max_cut_size: int = 1000
    stochastic_cut_size: int = 256
    stochastic_passes: int = 2
    stochastic_cut_sharing: int = 4
    gather_spacing: int = 0
    clamp: float = 0.02
    clamp_compensation: bool = True
    gather: str = "STOCHASTIC"
    lightcut_error: str = "TOTAL"
    tree_pairing: str = "PLOC"
    seeding: str = "BDPT"
    direct_light: str = "NEE"
    direct_samples: int = 64
    shading_samples: int = 0
    e1_samples: int = 256
    normalize_to_p: bool = False
    memory_budget_mb: int = 4096
    cluster: str = ""

    def __post_init__(self):
        if self.integrator not in INTEGRATORS:
            raise ValueError(f"unknown integrator {self.integrator!r}; expected one of {INTEGRATORS}")
        if min(self.samples, self.rough_samples) < 1:
            raise ValueError(f"samples and rough_samples must be >= 1, got {self.samples}, {self.rough_samples}")
        if self.max_depth < 1:
            raise ValueError(f"max_depth must be >= 1, got {self.max_depth}")
        if self.time_limit < 0:
            raise ValueError(f"time_limit must be >= 0, got {self.time_limit}")
        if self.batch_rays < 1024:
            raise ValueError(f"batch_rays must be >= 1024, got {self.batch_rays}")
        if self.gather not in GATHERS:
            raise ValueError(f"unknown gather {self.gather!r}; expected one of {GATHERS}")
        if self.lightcut_error not in LIGHTCUT_ERRORS:
            raise ValueError(f"unknown lightcut_error {self.lightcut_error!r}; expected one of {LIGHTCUT_ERRORS}")
        if self.tree_pairing not in TREE_PAIRINGS:
            raise ValueError(f"unknown tree_pairing {self.tree_pairing!r}; expected one of {TREE_PAIRINGS}")
        if self.seeding not in SEEDINGS:
            raise ValueError(f"unknown seeding {self.seeding!r}; expected one of {SEEDINGS}")
        if self.direct_light not in DIRECT_LIGHTS:
            raise ValueError(f"unknown direct_light {self.direct_light!r}; expected one of {DIRECT_LIGHTS}")
        if not 0 < self.max_error < 1:
            raise ValueError(f"max_error must be in (0, 1), got {self.max_error}")
        if self.iteration_start < 0:
            raise ValueError(f"iteration_start must be >= 0, got {self.iteration_start}")
        if self.iterations < 0:
            raise ValueError(f"iterations must be >= 0 (0 = until the time limit), got {self.iterations}")
        if self.chains_per_pixel <= 0 or self.chain_length < 1 or self.max_chains < 1 or self.min_chain_length < 1:
            raise ValueError("chains_per_pixel and max_chains must be > 0, chain_length and min_chain_length >= 1")
        if min(self.max_cut_size, self.stochastic_cut_size, self.stochastic_passes, self.stochastic_cut_sharing,
               self.e1_samples, self.direct_samples, self.seed_samples) < 1:
            raise ValueError("max_cut_size, stochastic_cut_size, stochastic_passes, stochastic_cut_sharing, "
                             "e1_samples, direct_samples and seed_samples must be >= 1")
        if self.shading_samples < 0:
            raise ValueError(f"shading_samples must be >= 0 (0 = automatic), got {self.shading_samples}")
        if self.gather_spacing < 0:
            raise ValueError(f"gather_spacing must be >= 0 (0 = automatic), got {self.gather_spacing}")
        if self.clamp < 0:
            raise ValueError(f"clamp must be >= 0, got {self.clamp}")
        if self.memory_budget_mb < 0:
            raise ValueError(f"memory_budget_mb must be >= 0 (0 = no limit), got {self.memory_budget_mb}")
        if not valid_cluster_address(self.cluster):
            raise ValueError(f"cluster must be '', 'local', 'auto', 'ray://host:port' or 'host:port', "
                             f"got {self.cluster!r}")

    @classmethod
    def from_dict(cls, d: dict) -> "RenderSettings":
        """Build settings from a dict; unknown keys raise ``ValueError``."""
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(d) - known)
        if unknown:
            raise ValueError(f"unknown render settings: {', '.join(unknown)}")
        return cls(**d)

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)

    @property
    def direct_vpls(self) -> bool:
        """ERCUTS chains and VPLs also carry direct light (``direct_light='VPL'``, the paper);
        the target class of :func:`~ercuts_core.integrators.ercuts.paths.is_target`."""
        return self.direct_light == "VPL"

    def shading_points(self, n_pixels: int) -> int:
        """Shading points per pixel of an ``n_pixels`` render: ``shading_samples``, or for 0
        the automatic choice (:data:`AUTO_SHADING_SAMPLES`)."""
        if self.shading_samples:
            return self.shading_samples
        for pixels, S in AUTO_SHADING_SAMPLES:
            if n_pixels < pixels:
                return S
        return 1

    def chain_plan(self, n_pixels: int) -> tuple[float, int]:
        """(C, N): the ER chains per iteration and their length for ``n_pixels`` pixels.
        C = c·n chains of ``chain_length`` steps up to ``max_chains``; beyond, the same
        mutation steps B = max_chains · chain_length spread over shorter chains,
        N = clip(B / (c·n), min_chain_length, chain_length), C = min(c·n, B / N)."""
        wanted = self.chains_per_pixel * n_pixels
        if wanted <= self.max_chains:
            return wanted, self.chain_length
        steps = self.max_chains * self.chain_length
        length = int(min(self.chain_length, max(self.min_chain_length, round(steps / wanted))))
        return min(wanted, steps / length), length

    def seed_rate(self, n_pixels: int) -> float:
        """Seed paths per pixel of an iteration: q = the share of the pixels that seed
        (1, or C / (c·n) when the chains' cap binds, :meth:`chain_plan`) times
        ``seed_samples``, but the extra samples only while they fit in
        :data:`SEED_SAMPLE_BUDGET`: max(q, min(seed_samples·q, budget / n)) (160×120: 4;
        from 640×480 up: q, as with one seed sample)."""
        wanted = self.chains_per_pixel * n_pixels
        chains, _ = self.chain_plan(n_pixels)
        q = min(1.0, chains / max(wanted, 1e-12))
        return max(q, min(self.seed_samples * q, SEED_SAMPLE_BUDGET / max(n_pixels, 1)))

    def replace(self, **changes) -> "RenderSettings":
        return dataclasses.replace(self, **changes)
