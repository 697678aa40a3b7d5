"""Render settings: one frozen dataclass holding every core parameter and its default.

The add-on's ``scene.ercuts`` PropertyGroup mirrors these fields one-to-one (same names,
defaults and ranges; a test checks it). :meth:`RenderSettings.from_dict` rejects unknown
keys, like pbrt-v4's ``ReportUnused``.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass, fields

INTEGRATORS = ("BDPT", "PATH")


@dataclass(frozen=True)
class RenderSettings:
    """Core render settings.

    Attributes:
        integrator: 'BDPT' (bidirectional path tracing with MIS) or 'PATH' (the
            reference unidirectional path tracer with next-event estimation).
        samples: samples per pixel.
        seed: random seed; the same seed and settings give the same image.
        max_depth: maximum number of bounces (path segments − 1); 1 = direct light only.
        rr_depth: bounces before Russian roulette starts.
        time_limit: seconds for the whole render (0 = none); the image rendered so far
            is returned when it runs out.
        film_transparent: alpha = coverage instead of 1.
        batch_rays: target rays per wavefront batch (memory vs. per-call overhead).
        threads: embreex threads per batch (0 = all cores).
    """

    integrator: str = "BDPT"
    samples: int = 16
    seed: int = 0
    max_depth: int = 8
    rr_depth: int = 3
    time_limit: float = 0.0
    film_transparent: bool = False
    batch_rays: int = 1 << 17
    threads: int = 0

    def __post_init__(self):
        if self.integrator not in INTEGRATORS:
            raise ValueError(f"unknown integrator {self.integrator!r}; expected one of {INTEGRATORS}")
        if self.samples < 1:
            raise ValueError(f"samples must be >= 1, got {self.samples}")
        if self.max_depth < 1:
            raise ValueError(f"max_depth must be >= 1, got {self.max_depth}")
        if self.time_limit < 0:
            raise ValueError(f"time_limit must be >= 0, got {self.time_limit}")
        if self.batch_rays < 1024:
            raise ValueError(f"batch_rays must be >= 1024, got {self.batch_rays}")

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

    def replace(self, **changes) -> "RenderSettings":
        return dataclasses.replace(self, **changes)
