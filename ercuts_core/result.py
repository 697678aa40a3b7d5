"""What a render returns: the image of the rendered window, timings and statistics."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray


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
        aovs: extra per-pixel images with the same (h, w) as ``image``
            (e.g. 'depth' (h, w, 1), 'normal' (h, w, 3), 'albedo' (h, w, 3)).
    """

    image: NDArray[np.float32]
    window: tuple[int, int, int, int]
    full_size: tuple[int, int]
    timings: dict[str, float] = field(default_factory=dict)
    stats: dict[str, float] = field(default_factory=dict)
    issues: list = field(default_factory=list)
    cancelled: bool = False
    aovs: dict[str, NDArray[np.float32]] = field(default_factory=dict)

    def summary(self) -> str:
        """One line: time, samples, rays per second, issues."""
        t = self.timings.get("total", 0.0)
        rays = self.stats.get("rays", 0)
        rate = rays / max(self.timings.get("render", t), 1e-9)
        st = self.stats
        parts = [f"{self.window[2]}x{self.window[3]} px", f"total {t:.2f} s"]
        if "chains" in st:   # ERCUTS: one gather pass after the rough BDPT image
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
        if self.cancelled:
            parts.append("CANCELLED")
        return " | ".join(parts)
