"""Measurement camera (paper §VI-A): a virtual camera at the eye that photographs the projected image where it
really lands — on the actual flat, tilted or pushed sheet — and measures the cylinder's sizes in mm.

Independent of the correction code: the true sheet is the membrane sampled on a G×G grid (the layout of
:class:`messages.SheetState` ``membrane``), interpolated bilinearly, and each camera ray is intersected with
it by bracketing bisection (the correction uses Newton on the analytic series). Light path, traced backwards:
camera pixel → ray from the eye → hit X on the true sheet → projector pixel that lights X (the TRUE
projector: pinhole K, R, P plus its OpenCV lens distortion D, as ``cv2.projectPoints``) → bilinear sample of
the projector image (``cv2.remap``). Rays that miss the sheet see black.

In the honest twin (``flexsheet experiment correction --twin realistic``) the sheet, the projector and its
distortion passed to :meth:`MeasurementCamera.photograph` are the hidden truth's
(:class:`flexsheet.twin.truth.TwinTruth`); the projector image was drawn by the renderer with the
*calibrated* ones (``display.yaml``). This module never sees which is which.

The camera's image plane is the imaginary screen itself (1 camera pixel = ``pixel`` m on the screen), so
sizes are read directly in screen millimetres as in the paper ("1 pixel corresponds to 0.7 mm on the imaginary
screen").
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from flexsheet.model import geometry
from flexsheet.model.projector import Projector
from flexsheet.model.sheet import SheetSurface

__all__ = ["MeasurementCamera", "measure_sizes", "measure_edges", "trace_to_sheet", "projector_pixels"]


def projector_pixels(points: np.ndarray, projector: Projector, distortion=None) -> tuple[np.ndarray,
                                                                                         np.ndarray]:
    """Projector pixel (N, 2) (x right, y down, pixel centres at integers) that lights each display-frame
    point (N, 3) m, and a mask (N,) of points in front of the projector. Pinhole K, R, P of ``projector`` and
    the OpenCV distortion ``distortion`` (k1, k2, p1, p2, k3) (5,) or None, as ``cv2.projectPoints``
    (Brown–Conrady model; OpenCV docs, "Camera Calibration and 3D Reconstruction"). Raises ``ValueError`` for
    a distortion that is not 5 finite numbers."""
    pts = np.asarray(points, dtype=float)
    xc = (pts - np.asarray(projector.position, float)) @ np.asarray(projector.R, float)
    front = xc[:, 2] > 1e-9
    z = np.where(front, xc[:, 2], 1.0)
    x, y = xc[:, 0] / z, xc[:, 1] / z
    if distortion is not None:
        D = np.asarray(distortion, dtype=float).ravel()
        if D.shape != (5,) or not np.all(np.isfinite(D)):
            raise ValueError("distortion must be 5 finite OpenCV coefficients (k1, k2, p1, p2, k3), got "
                             f"{distortion!r}")
        k1, k2, p1, p2, k3 = D
        r2 = x * x + y * y
        radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
        x, y = (x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x),
                y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y)
    K = np.asarray(projector.K, float)
    uv = np.column_stack([K[0, 0] * x + K[0, 1] * y + K[0, 2], K[1, 1] * y + K[1, 2]])
    return uv, front


def _bilinear(grid: np.ndarray, a: float, b: float, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Bilinear interpolation of ``grid`` (n, n) over u ∈ [−a, a] × v ∈ [−b, b] (clamped)."""
    n0, n1 = grid.shape
    fu = np.clip((u + a) / (2 * a) * (n0 - 1), 0, n0 - 1 - 1e-9)
    fv = np.clip((v + b) / (2 * b) * (n1 - 1), 0, n1 - 1 - 1e-9)
    i, j = fu.astype(int), fv.astype(int)
    tu, tv = fu - i, fv - j
    return ((1 - tu) * (1 - tv) * grid[i, j] + tu * (1 - tv) * grid[i + 1, j]
            + (1 - tu) * tv * grid[i, j + 1] + tu * tv * grid[i + 1, j + 1])


def trace_to_sheet(origin, dirs: np.ndarray, sheet: SheetSurface, grid: np.ndarray | None = None,
                   iters: int = 40) -> tuple[np.ndarray, np.ndarray]:
    """Hit points (N, 3) m of rays ``origin`` (3,) + t·``dirs`` (N, 3) with the true sheet, and a hit mask
    (N,).

    ``grid``: deflection (G, G) m over the sheet (None: flat). The hit is bracketed between the plane
    (depth 0) and depth max(grid) and found by ``iters`` bisection steps on depth(t) − w(t); rays parallel to
    the sheet or landing outside |u| ≤ a, |v| ≤ b are misses."""
    o = np.asarray(origin, dtype=float)
    d = np.asarray(dirs, dtype=float)
    n, eu, ev, so = sheet.normal, sheet.axis_u, sheet.axis_v, sheet.origin
    dn = -(d @ n)
    par = np.abs(dn) < 1e-12
    dn = np.where(par, 1e-12, dn)
    h0 = -((o - so) @ n)                          # depth of the ray origin (negative: in front)
    t0 = -h0 / dn                                 # depth 0
    if grid is None or not np.any(grid > 0):
        t = t0
    else:
        wmax = float(grid.max()) + 1e-6
        lo, hi = t0, (wmax - h0) / dn
        pu, pv = (o - so) @ eu, (o - so) @ ev
        du, dv = d @ eu, d @ ev
        for _ in range(iters):
            mid = 0.5 * (lo + hi)
            f = ((h0 + mid * dn)
                 - _bilinear(grid, sheet.half_span, sheet.half_width, pu + mid * du, pv + mid * dv))
            below = f < 0.0
            lo = np.where(below, mid, lo)
            hi = np.where(below, hi, mid)
        t = 0.5 * (lo + hi)
    x = o + t[:, None] * d
    rel = x - so
    hit = (~par) & (t > 0) & (np.abs(rel @ eu) <= sheet.half_span) & (np.abs(rel @ ev) <= sheet.half_width)
    return x, hit


@dataclass
class MeasurementCamera:
    """Virtual camera at ``eye`` whose image plane is the imaginary screen.

    ``pixel`` m per camera pixel on the screen; ``extent`` (width, height) m of the photographed screen area
    centred on ``screen_point``; the image's x axis points to the user's right (+y), its rows go down (−z),
    for the default screen normal +x. ``grid_n``: samples per side of the true membrane grid.
    """

    eye: np.ndarray = field(default_factory=lambda: geometry.EYE.copy())
    pixel: float = 0.00035
    extent: tuple[float, float] = (0.24, 0.18)
    screen_point: np.ndarray = field(default_factory=lambda: geometry.SCREEN_POINT.copy())
    screen_normal: np.ndarray = field(default_factory=lambda: geometry.SCREEN_NORMAL.copy())
    grid_n: int = 241

    def __post_init__(self) -> None:
        if not (self.pixel > 0 and math.isfinite(self.pixel)):
            raise ValueError(f"pixel must be > 0, got {self.pixel!r}")
        no = np.asarray(self.screen_normal, dtype=float)
        no = no / np.linalg.norm(no)
        up = np.array([0.0, 0.0, 1.0])
        right = np.cross(up, no)       # +y for no = +x: the user's right (the user faces −x)
        w, h = int(round(self.extent[0] / self.pixel)), int(round(self.extent[1] / self.pixel))
        xs = (np.arange(w) - (w - 1) / 2) * self.pixel
        zs = ((h - 1) / 2 - np.arange(h)) * self.pixel
        X, Z = np.meshgrid(xs, zs)
        self.shape = (h, w)
        self.xs, self.zs = xs, zs
        self.points = (np.asarray(self.screen_point, dtype=float) + X[..., None] * right + Z[..., None] * up
                       ).reshape(-1, 3)

    def photograph(self, projector_image: np.ndarray, projector: Projector, sheet: SheetSurface,
                   distortion=None) -> np.ndarray:
        """What the eye sees: (h, w) float32 in [0, 1] (grey level of ``projector_image`` (H, W) or (H, W,
        3)).

        ``projector``/``distortion``: the projector that really lights the sheet (pinhole + OpenCV D (5,),
        None: pinhole); ``sheet``: the TRUE sheet (its membrane, if any, is sampled on the grid and traced
        independently). Raises ``ValueError`` for a bad distortion."""
        import cv2

        img = np.asarray(projector_image, dtype=np.float32)
        if img.ndim == 3:
            img = img.mean(axis=2)
        if img.max() > 1.0:
            img = img / 255.0
        grid = sheet.membrane.grid(self.grid_n) if sheet.membrane is not None else None
        v = np.asarray(self.eye, dtype=float)
        dirs = self.points - v
        x, hit = trace_to_sheet(v, dirs, sheet, grid)
        uv, front = projector_pixels(x, projector, distortion)
        uv[~hit | ~front] = -10.0
        mx = uv[:, 0].reshape(self.shape).astype(np.float32)
        my = uv[:, 1].reshape(self.shape).astype(np.float32)
        return cv2.remap(img, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0.0)


def _profile_span(profile: np.ndarray) -> tuple[float, float]:
    """Sub-pixel first/last crossings of 0.5 of a 1-D profile (indices)."""
    above = np.nonzero(profile >= 0.5)[0]
    if len(above) == 0:
        raise ValueError("the object is not visible in the photograph")
    i0, i1 = above[0], above[-1]
    a = i0 - (profile[i0] - 0.5) / max(profile[i0] - profile[i0 - 1], 1e-9) if i0 > 0 else float(i0)
    b = (i1 + (profile[i1] - 0.5) / max(profile[i1] - profile[i1 + 1], 1e-9) if i1 < len(profile) - 1
         else float(i1))
    return float(a), float(b)


def _row(img: np.ndarray, r: float) -> np.ndarray:
    i = int(np.floor(r))
    t = r - i
    return (1 - t) * img[i] + t * img[min(i + 1, img.shape[0] - 1)]


def measure_sizes(img: np.ndarray, pixel: float, inset: float = 0.1) -> dict[str, float]:
    """Sizes of the cylinder's image (m): ``h`` height at the centre column, ``w`` width at the middle row,
    ``u``/``d`` widths ``inset``·h inside the top/bottom edges (paper Fig. 11's upside/downside widths).

    Edges are the 0.5 crossings of intensity profiles, interpolated to sub-pixel (the image is anti-aliased).
    ``img`` (h, w) in [0, 1]; ``pixel`` m per pixel. Raises ``ValueError`` if nothing is visible."""
    img = np.asarray(img, dtype=float)
    cx = (img.shape[1] - 1) / 2.0
    col = 0.5 * (img[:, int(np.floor(cx))] + img[:, int(np.ceil(cx))])
    top, bot = _profile_span(col)
    h = bot - top
    out = {"h": h * pixel}
    for name, r in (("u", top + inset * h), ("d", bot - inset * h), ("w", 0.5 * (top + bot))):
        a, b = _profile_span(_row(img, r))
        out[name] = (b - a) * pixel
    return out


def measure_edges(img: np.ndarray, pixel: float) -> dict[str, float]:
    """Edges (m on the screen, from the photograph's centre; x right, z up) of the object's image: ``top`` and
    ``bottom`` of the centre column, ``left`` and ``right`` of the row halfway between them (0.5 crossings, as
    :func:`measure_sizes`). Raises ``ValueError`` if nothing is visible."""
    img = np.asarray(img, dtype=float)
    cy, cx = (img.shape[0] - 1) / 2.0, (img.shape[1] - 1) / 2.0
    col = 0.5 * (img[:, int(np.floor(cx))] + img[:, int(np.ceil(cx))])
    top, bot = _profile_span(col)
    a, b = _profile_span(_row(img, 0.5 * (top + bot)))
    return {"top": (cy - top) * pixel, "bottom": (cy - bot) * pixel, "left": (a - cx) * pixel,
            "right": (b - cx) * pixel}
