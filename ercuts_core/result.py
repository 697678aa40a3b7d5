"""What a render returns: the image of the rendered window, timings and statistics."""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

#: ``stats`` keys grouped under "vpl" and "cuts" in :meth:`RenderResult.report_dict`.
VPL_KEYS = ("P", "P_all", "seed_paths", "chains", "chain_steps", "chain_states", "vpls_before_merge",
            "vpls_after_merge", "vpls", "vpls_emitter", "vpls_unlit_fallback", "e1_samples",
            "vpls_kept_for_time_limit", "vpl_energy_ratio", "nan_acceptances")
CUT_KEYS = ("cut_size_mean", "cut_size_max", "cut_bound_unmet", "max_error_for_time_limit", "cut_cap_for_time_limit",
            "paced_points_for_time_limit", "gather_shadow_rays",
            "clamped_energy", "compensated_points", "compensated_energy", "compensation_seconds", "compensation_rays",
            "gather_incomplete")


@dataclass
class RenderResult:
    """Result of :func:`ercuts_core.render`.

    Attributes:
        image: (h, w, 4) float32 linear RGBA of the rendered window, **top row first**.
        window: (x0, y0, w, h) of the rendered window in full-frame pixels, x from the
            left and y from the **top** (the whole frame unless a border was used).
        full_size: (width, height) of the full frame.
        timings: seconds per phase, e.g. {'validate': .., 'build': .., 'render': ..,
            'total': ..}.
        stats: counters, e.g. {'rays': .., 'samples': .., 'nonfinite_samples': ..}.
        issues: messages from validation and rendering (see :mod:`ercuts_core.validate`).
        cancelled: True when ``progress`` returned False or ``time_limit`` ran out.
        stopped_by: why the render stopped early: None (it finished), 'time_limit' (the
            time budget was used: a normal end) or 'cancel' (``progress`` returned False:
            the user or the host interrupted it, so the image is incomplete).
        aovs: extra per-pixel float32 images with the same (h, w) as ``image``, top row
            first: 'depth' (h, w, 1), 'normal' and 'albedo' (h, w, 3) (first hit); the light
            passes 'emission', 'direct', 'indirect' (h, w, 3) (path classes 0, 1, ≥ 2
            scattering vertices, :mod:`ercuts_core.film`; they sum to the image RGB); ERCUTS
            only: 'cut_size', 'vpl_density', 'chain_deposits' (h, w, 1) and 'er_caustic'
            (h, w, 3) (:mod:`ercuts_core.integrators.ercuts`).
    """

    image: NDArray[np.float32]
    window: tuple[int, int, int, int]
    full_size: tuple[int, int]
    timings: dict[str, float] = field(default_factory=dict)
    stats: dict[str, float] = field(default_factory=dict)
    issues: list = field(default_factory=list)
    cancelled: bool = False
    aovs: dict[str, NDArray[np.float32]] = field(default_factory=dict)
    stopped_by: str | None = None

    def summary(self) -> str:
        """One line: time, samples, rays per second, issues."""
        t = self.timings.get("total", 0.0)
        rays = self.stats.get("rays", 0)
        rate = rays / max(self.timings.get("render", t), 1e-9)
        st = self.stats
        parts = [f"{self.window[2]}x{self.window[3]} px", f"total {t:.2f} s"]
        if "chains" in st:   # ERCUTS: one gather pass after the rough BDPT image (per iteration)
            if st.get("iterations", 1) > 1:
                parts.append(f"{int(st['iterations'])} iterations (first:)")
            parts += [f"BDPT {int(st.get('bdpt_samples', 0))} spp",
                      f"{int(st['chains'])} chains x {int(st.get('chain_steps', 0))} steps",
                      f"{int(st.get('vpls', 0))} VPLs",
                      f"mean cut {st.get('cut_size_mean', 0):.0f}"]
        else:
            parts.append(f"{int(st.get('samples', 0))} spp")
        parts += [
            f"{rays / 1e6:.2f} M rays ({rate / 1e6:.2f} M rays/s)",
            f"non-finite samples {int(st.get('nonfinite_samples', 0))}",
        ]
        if self.stopped_by == "time_limit":
            parts.append("time limit reached")
        elif self.cancelled:
            parts.append("CANCELLED")
        return " | ".join(parts)

    def report_dict(self, settings: Any = None) -> dict:
        """A JSON-serializable record of the render (api.md; the add-on's JSON sidecar).

        Args:
            settings: the :class:`~ercuts_core.settings.RenderSettings` (or a dict of them)
                the render used; recorded as given, with its seed.
        Returns:
            {'settings', 'seed', 'window', 'full_size', 'cancelled', 'stopped_by', 'timings',
            'vpl', 'cuts', 'stats', 'issues', 'summary'}: plain dicts, lists, str, int, float (non-finite
            numbers become None), so ``json.dumps`` accepts it.
        """
        if dataclasses.is_dataclass(settings):
            settings = dataclasses.asdict(settings)
        st = self.stats
        x0, y0, w, h = self.window
        out = {
            "settings": settings,
            "seed": settings.get("seed") if isinstance(settings, dict) else None,
            "window": {"x0": x0, "y0": y0, "width": w, "height": h},
            "full_size": list(self.full_size),
            "cancelled": self.cancelled,
            "stopped_by": self.stopped_by,
            "timings": self.timings,
            "vpl": {k: st[k] for k in VPL_KEYS if k in st},
            "cuts": {k: st[k] for k in CUT_KEYS if k in st},
            "stats": st,
            "issues": [_issue_dict(i) for i in self.issues],
            "summary": self.summary(),
        }
        return _jsonable(out)


def _issue_dict(issue: Any) -> dict:
    """An :class:`~ercuts_core.validate.Issue` (or a plain message) as a dict."""
    if dataclasses.is_dataclass(issue):
        return dataclasses.asdict(issue)
    return {"message": str(issue)}


def _jsonable(x: Any) -> Any:
    """``x`` with numpy scalars/arrays, tuples and non-finite floats made JSON-safe."""
    if isinstance(x, dict):
        return {str(k): _jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_jsonable(v) for v in x]
    if isinstance(x, np.ndarray):
        return _jsonable(x.tolist())
    if isinstance(x, (bool, np.bool_)):
        return bool(x)
    if isinstance(x, (int, np.integer)):
        return int(x)
    if isinstance(x, (float, np.floating)):
        return float(x) if math.isfinite(x) else None
    if x is None or isinstance(x, str):
        return x
    return str(x)
