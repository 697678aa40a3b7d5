"""Camera model: Blender's view plane, primary rays, and importance for light tracing.

The view plane follows Blender's ``BKE_camera_params_compute_viewplane``: the *fitted*
image dimension (chosen by ``sensor_fit``; AUTO fits the larger of W·aspect_x and
H·aspect_y, using ``sensor_width`` in both cases) spans ``sensor/lens`` at unit distance
(perspective) or ``ortho_scale`` (orthographic); the other dimension follows the image
aspect; ``shift_x``/``shift_y`` move the plane by that many fitted-dimension extents.
This equals ``Camera.view_frame()`` scaled to z = −1.

Raster coordinates are continuous full-frame pixels: x to the right from the left edge,
y downward from the top edge; pixel (i, j) covers [i, i+1] × [j, j+1].

Importance (for the t = 1 light-tracing strategy of BDPT) is normalised per pixel:
a pinhole camera has W_e(ω) = 1 / (A_pix · cos⁴θ), with A_pix the area of one pixel on
the z = 1 plane [Veach 1997 §10.8; pbrt-v3 PerspectiveCamera::We].

Depth of field (perspective cameras with ``aperture_radius`` > 0) is Cycles' thin lens
(``kernel/camera/camera.h`` ``camera_sample_perspective``): a point l on the aperture (a
disk, or a regular polygon of ``aperture_blades`` rotated by ``aperture_rotation``, its x
divided by ``aperture_ratio``; ``camera_sample_aperture``), the ray from l through the point
F of the raster position on the plane in focus at depth ``focus_distance``. The lens point is
uniform in the aperture, so the importance of a lens point and direction is the pinhole's
divided by the aperture area, and every density the integrators use keeps its pinhole form
with the lens point as the ray origin: ``pdf_dir`` = 1/(A_window·cos³θ) (F is uniform over
the window on the focal plane) and the connection factor W_e·|cos|/d² ÷ p_A(l) =
1/(A_pix·cos³θ·d²) [pbrt-v3 PerspectiveCamera::Sample_Wi with a lens]. Everything that
makes camera rays or connects to the camera draws the lens samples itself
(:meth:`Camera.lens_samples`: None, and no random numbers, for a pinhole).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from .description import CameraDesc
from .sampling import sample_regular_polygon, sample_uniform_disk_concentric


@dataclass(frozen=True)
class Window:
    """Rendered window in full-frame pixels, y from the top."""

    x0: int
    y0: int
    width: int
    height: int

    @property
    def n_pixels(self) -> int:
        return self.width * self.height

    @property
    def rect(self) -> tuple[int, int, int, int]:
        """(x0, y0, width, height): the ``window`` tuple of :class:`RenderResult`."""
        return (self.x0, self.y0, self.width, self.height)

    def raster(self, pix: NDArray) -> NDArray:
        """(N, 2) int64 full-frame raster position of the top-left corner of window pixels
        ``pix`` (N,) (row-major, top row first)."""
        return np.stack([self.x0 + pix % self.width, self.y0 + pix // self.width], axis=1)

    def pixel_xy(self, raster: NDArray, clip: bool = False) -> tuple[NDArray, NDArray]:
        """(ix, iy) (N,) int64 window column and row of full-frame raster positions (N, 2);
        with ``clip``, clamped into the window."""
        ix = np.floor(raster[:, 0]).astype(np.int64) - self.x0
        iy = np.floor(raster[:, 1]).astype(np.int64) - self.y0
        if clip:
            ix, iy = np.clip(ix, 0, self.width - 1), np.clip(iy, 0, self.height - 1)
        return ix, iy

    def pixel(self, raster: NDArray, clip: bool = False) -> tuple[NDArray, NDArray]:
        """((N,) window pixel index, (N,) inside the window) of raster positions (N, 2); with
        ``clip``, positions outside are clamped to the nearest pixel (all inside)."""
        ix, iy = self.pixel_xy(raster, clip)
        inside = (ix >= 0) & (ix < self.width) & (iy >= 0) & (iy < self.height)
        return iy * self.width + ix, inside


def view_plane(desc: CameraDesc) -> tuple[float, float, float, float]:
    """(xmin, xmax, ymin, ymax) of the image plane at z = −1 (persp) or z = 0 (ortho), camera space."""
    ax, ay = desc.pixel_aspect_x, desc.pixel_aspect_y
    wx, wy = desc.width * ax, desc.height * ay
    fit = desc.sensor_fit
    if fit == "AUTO":
        fit = "HORIZONTAL" if wx >= wy else "VERTICAL"
        sensor = desc.sensor_width
    else:
        sensor = desc.sensor_width if fit == "HORIZONTAL" else desc.sensor_height
    extent = desc.ortho_scale if desc.projection == "ORTHO" else sensor / desc.lens
    if fit == "HORIZONTAL":
        ext_x, ext_y = extent, extent * wy / wx
    else:
        ext_x, ext_y = extent * wx / wy, extent
    cx, cy = desc.shift_x * extent, desc.shift_y * extent
    return (cx - 0.5 * ext_x, cx + 0.5 * ext_x, cy - 0.5 * ext_y, cy + 0.5 * ext_y)


def render_window(desc: CameraDesc) -> Window:
    """The pixels to render: the border window (Blender truncation rules) or the whole frame."""
    W, H = desc.width, desc.height
    if not desc.use_border:
        return Window(0, 0, W, H)
    bx0, by0, bx1, by1 = desc.border
    x0, x1 = int(bx0 * W), int(bx1 * W)
    yb0, yb1 = int(by0 * H), int(by1 * H)
    return Window(x0, H - yb1, x1 - x0, yb1 - yb0)


class Camera:
    """Primary-ray generation and pinhole importance for one :class:`CameraDesc`."""

    def __init__(self, desc: CameraDesc):
        self.desc = desc
        self.width, self.height = desc.width, desc.height
        self.window = render_window(desc)
        self.ortho = desc.projection == "ORTHO"
        m = np.asarray(desc.world_from_camera, np.float64)
        rot = m[:3, :3]
        # Remove any scale the caller left in the matrix (columns become unit vectors).
        self.rotation = rot / np.linalg.norm(rot, axis=0, keepdims=True)
        self.position = m[:3, 3].copy()
        self.forward = -self.rotation[:, 2]
        self.xmin, self.xmax, self.ymin, self.ymax = view_plane(desc)
        self.pixel_area = (self.xmax - self.xmin) * (self.ymax - self.ymin) / (self.width * self.height)
        self.window_area = self.pixel_area * self.window.n_pixels
        #: True when the camera is a delta in direction (orthographic): no t = 1 connections.
        self.is_delta_direction = self.ortho
        #: Thin lens: aperture radius [m] (0 = pinhole; orthographic cameras have none).
        self.lens_radius = 0.0 if self.ortho else max(float(desc.aperture_radius), 0.0)
        self.has_lens = self.lens_radius > 0
        self.focus = float(desc.focus_distance)

    # ----------------------------------------------------------- thin lens
    def lens_samples(self, rng: np.random.Generator, n: int) -> NDArray | None:
        """(n, 2) uniforms for the aperture, or None for a pinhole (drawing nothing, so
        renders without depth of field keep their random streams)."""
        return rng.random((n, 2)) if self.has_lens else None

    def lens_points(self, u: NDArray) -> NDArray:
        """(N, 3) camera-space points of the aperture (z = 0) from (N, 2) uniforms: Cycles
        ``camera_sample_aperture`` (concentric disk or blade polygon, x ÷ ratio) × radius."""
        d = self.desc
        if d.aperture_blades >= 3:
            ab = sample_regular_polygon(u, d.aperture_blades, d.aperture_rotation)
        else:
            ab = sample_uniform_disk_concentric(u)
        ab = ab * self.lens_radius
        ab[:, 0] /= d.aperture_ratio
        return np.column_stack([ab, np.zeros(len(ab))])

    def _to_camera(self, p: NDArray) -> NDArray:
        return (p - self.position) @ self.rotation

    def _to_world(self, q: NDArray) -> NDArray:
        return self.position + q @ self.rotation.T

    def _lens_rays(self, raster: NDArray, lens: NDArray) -> tuple[NDArray, NDArray]:
        """Rays from camera-space lens points (N, 3) through the raster positions' points on
        the plane in focus (z = −focus)."""
        target = self.plane_point(raster) * self.focus
        d = target - lens
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        return self._to_world(lens), d @ self.rotation.T

    def rays_from(self, raster: NDArray, origin: NDArray) -> tuple[NDArray, NDArray]:
        """Rays through raster positions (N, 2) from given world points of the aperture
        (N, 3) (the ER lens perturbation keeps a path's lens point); a pinhole ignores them."""
        if not self.has_lens:
            return self.generate_rays(raster)
        return self._lens_rays(raster, self._to_camera(origin) * [1.0, 1.0, 0.0])

    def lens_point_of(self, raster: NDArray, p: NDArray) -> NDArray:
        """(N, 3) world point of the aperture whose ray through raster position (N, 2) passes
        the world point p (N, 3): the line from p through the raster's point in focus, met
        with the lens plane. The pinhole for a camera without a lens."""
        if not self.has_lens:
            return np.broadcast_to(self.position, p.shape).copy()
        target = self.plane_point(raster) * self.focus
        q = self._to_camera(p)
        t = target[:, 2] / np.where(target[:, 2] - q[:, 2] != 0, target[:, 2] - q[:, 2], 1e-300)
        lens = target + (q - target) * t[:, None]
        lens[:, 2] = 0.0
        return self._to_world(lens)

    # ----------------------------------------------------------- primary rays
    def plane_point(self, raster: NDArray) -> NDArray:
        """(N, 2) raster → (N, 3) camera-space points on the image plane."""
        x = self.xmin + raster[:, 0] / self.width * (self.xmax - self.xmin)
        y = self.ymax - raster[:, 1] / self.height * (self.ymax - self.ymin)
        z = np.zeros_like(x) if self.ortho else -np.ones_like(x)
        return np.stack([x, y, z], axis=1)

    def generate_rays(self, raster: NDArray, u_lens: NDArray | None = None) -> tuple[NDArray, NDArray]:
        """World-space rays through raster positions.

        Args:
            raster: (N, 2) float64 full-frame raster coordinates.
            u_lens: (N, 2) aperture uniforms (:meth:`lens_samples`); required with depth of
                field, ignored by a pinhole.
        Returns:
            origins (N, 3), unit directions (N, 3), float64.
        """
        if self.has_lens:
            if u_lens is None:
                raise ValueError("a camera with depth of field needs lens samples (Camera.lens_samples)")
            return self._lens_rays(raster, self.lens_points(u_lens))
        q = self.plane_point(raster)
        if self.ortho:
            o = self.position + q @ self.rotation.T
            d = np.broadcast_to(self.forward, o.shape).copy()
            return o, d
        d = q @ self.rotation.T
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        return np.broadcast_to(self.position, d.shape).copy(), d

    def cos_theta(self, d: NDArray) -> NDArray:
        """(N,) cosine between unit world directions and the viewing axis."""
        return d @ self.forward

    def pdf_dir(self, d: NDArray) -> NDArray:
        """(N,) solid-angle density of a camera ray direction for one sample spread
        uniformly over the rendered window: 1/(A_window·cos³θ) (perspective only)."""
        c = np.maximum(self.cos_theta(d), 1e-12)
        return 1.0 / (self.window_area * c**3)

    def pdf_area(self, d: NDArray, dist: NDArray, cos_hit: NDArray) -> NDArray:
        """(N,) area density at the first hit x1 of a camera ray (pdf_dir converted to area).

        Orthographic: the ray origin is uniform over the window area on the film and
        the direction is fixed, so p_A(x1) = |cos_hit| / A_window.
        """
        if self.ortho:
            return np.abs(cos_hit) / self.window_area
        return self.pdf_dir(d) * np.abs(cos_hit) / np.maximum(dist * dist, 1e-60)

    # ----------------------------------------------------------- light tracing
    def raster_of(self, p: NDArray, origin: NDArray | None = None) -> tuple[NDArray, NDArray]:
        """Project world points to raster coordinates (through the aperture point ``origin``
        (N, 3) with depth of field: where the ray origin → p crosses the plane in focus).

        Returns:
            raster (N, 2) and valid (N,) (in front of the camera and inside the window).
        """
        q = (p - self.position) @ self.rotation
        depth = -q[:, 2]
        if self.ortho:
            x, y = q[:, 0], q[:, 1]
            front = depth > 0
        elif origin is not None and self.has_lens:
            lens = self._to_camera(origin) * [1.0, 1.0, 0.0]
            front = depth > 1e-12
            t = self.focus / np.where(front, depth, 1.0)
            focal = lens + (q - lens) * t[:, None]         # on the plane z = −focus
            x, y = focal[:, 0] / self.focus, focal[:, 1] / self.focus
        else:
            front = depth > 1e-12
            safe = np.where(front, depth, 1.0)
            x, y = q[:, 0] / safe, q[:, 1] / safe
        rx = (x - self.xmin) / (self.xmax - self.xmin) * self.width
        ry = (self.ymax - y) / (self.ymax - self.ymin) * self.height
        raster = np.stack([rx, ry], axis=1)
        w = self.window
        inside = (rx >= w.x0) & (rx < w.x0 + w.width) & (ry >= w.y0) & (ry < w.y0 + w.height)
        return raster, front & inside

    def connect(self, p: NDArray, u_lens: NDArray | None = None) -> "CameraConnection":
        """Connect scene points to the pinhole, or to aperture points from (N, 2) uniforms
        ``u_lens`` with depth of field (BDPT t = 1, light tracing).

        The pixel measurement of light leaving ``p`` toward the camera with radiance L is
        ``L · |cos_p| · factor`` per unit area at p, where
        ``factor = W_e·|cos_cam|/d² = 1/(A_pix·cos³θ·d²)`` (d and θ from the lens point;
        the uniform lens density cancels the aperture area of W_e, module docstring).
        """
        n = len(p)
        if self.ortho:
            z = np.zeros(n)
            return CameraConnection(np.zeros((n, 2)), np.zeros((n, 3)), z, z, np.zeros(n, bool),
                                    np.zeros((n, 3)))
        if self.has_lens:
            if u_lens is None:
                raise ValueError("a camera with depth of field needs lens samples (Camera.lens_samples)")
            origin = self._to_world(self.lens_points(u_lens))
            raster, valid = self.raster_of(p, origin)
        else:
            origin = np.broadcast_to(self.position, p.shape)
            raster, valid = self.raster_of(p)
        to_cam = origin - p
        dist = np.linalg.norm(to_cam, axis=1)
        wi = to_cam / np.maximum(dist, 1e-30)[:, None]
        cos_cam = -(wi @ self.forward)
        valid &= (cos_cam > 1e-8) & (dist > 0)
        c = np.where(valid, cos_cam, 1.0)
        factor = np.where(valid, 1.0 / (self.pixel_area * c**3 * np.maximum(dist * dist, 1e-60)), 0.0)
        return CameraConnection(raster, wi, dist, factor, valid, origin)


@dataclass
class CameraConnection:
    """Result of :meth:`Camera.connect` for N points.

    Attributes:
        raster: (N, 2) full-frame raster position of each point's image.
        wi: (N, 3) unit direction from the point toward the camera.
        dist: (N,) distance to the camera [m].
        factor: (N,) W_e·|cos_cam|/d² = 1/(A_pix·cos³θ·d²) (0 where invalid).
        valid: (N,) visible-in-window and in front of the camera (occlusion not tested).
        origin: (N, 3) the camera point connected to: the pinhole or the sampled lens point
            (the end of the shadow ray).
    """

    raster: NDArray
    wi: NDArray
    dist: NDArray
    factor: NDArray
    valid: NDArray
    origin: NDArray
