"""Table I metrics of the paper (Fig. 9): position error Δd and angle error Δθ of the stroking sheet (pure).

Paper §V-C, Fig. 9: D is the fingertip position measured by the camera, D′ the fingertip position the
sheet presents, θ and θ′ the angles of the object's tangent plane at D and D′; Δd = |DD′|, Δθ = |θ − θ′|.
We make the definitions exact for any shape and sheet pose:

* D = the measured fingertip projected onto the virtual surface by the planner's rule
  (:meth:`flexsheet.model.shape_base.Shape.project`) — the point the sheet should present.
* D′ = the point where the *actual* sheet plane (origin, normal) touches the object: the support point in
  the sheet's normal direction (:meth:`Shape.support`, ties on flat directions broken toward D).
* θ′ is the sheet plane's orientation itself, so Δθ = the angle between the object's normal at D and the
  actual sheet normal (for the paper's cylinder this is exactly |θ − θ′| around the axis).
* ``gap`` (extra): distance of D′ from the sheet plane along its normal (the sheet floating off, > 0, or
  cutting into, < 0, the virtual surface) — zero when the sheet is exactly tangent.
* Fig. 9 is a cross-section: the **normal section along the stroke**, the plane through D spanned by the
  object's true normal n(D) and the stroke's direction t there (any scene: :func:`stroke_tangents` gives t
  from the scene's path). The sheet normal's component along the section's binormal b = n × t is removed
  before D′ and Δθ are computed (it is small, and would otherwise make the support point jump along b). On the
  paper's cylinder the stroke runs around the axis, so b is the axis and this is exactly the cylinder's
  cross-section; without tangents a shape with an ``axis`` (the cylinder) uses that cross-section directly
  (the same numbers, tested). Both the in-process experiment (:mod:`flexsheet.experiments.stroke_model`) and
  the report of a recorded run (:mod:`flexsheet.analysis.report`) get their rows from :func:`table1_row`, and
  the paper's numbers from :data:`PAPER_TABLE1`.

A bias common to D and the sheet (e.g. a camera calibration offset, the paper's 2.95 mm) cancels in Δd,
which is why the paper's Δd has a small standard deviation.

**Δd, two conventions.** Δθ is the headline (it does not depend on a length convention). Our Δd = |DD′| is
the chord between the two contact points on the cylinder, = 2R·sin(Δθ/2) ≈ R·Δθ (``dd_mean_mm``). Both rows
of the paper's Table I have Δd/Δθ = 0.443 mm/0.359° = 0.277 mm/0.225° = 70.7 mm/rad = 2R, the cylinder's
*diameter*; to compare like for like every row also carries ``dd_2r_mean_mm`` = 2R·Δθ
(:data:`DD_CONVENTION`). For shapes without a radius only ``dd_mean_mm`` is given.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from flexsheet.model.shape_base import Shape
from flexsheet.planning.shape import planner_shape

__all__ = ["StrokeErrors", "stroke_errors", "presented_contacts", "table1", "summarize", "table1_row",
           "PAPER_TABLE1", "TARGET_FACTOR", "FELT_TARGET_FACTOR", "target", "section_normals",
           "DD_CONVENTION", "paper_dd_ratio",
           "stroke_tangents", "scene_table1_row", "errors_row", "STROKE_MODES", "segment_key"]

#: the paper's Table I (Furukawa et al., §V-C): moving time (s, as the row key) → means and population
#: standard deviations of Δd (mm) and Δθ (deg) over the moving phase
PAPER_TABLE1: dict[str, dict[str, float]] = {
    "10": {"dd_mean_mm": 0.443, "dd_std_mm": 0.0330, "dtheta_mean_deg": 0.359, "dtheta_std_deg": 0.267},
    "30": {"dd_mean_mm": 0.277, "dd_std_mm": 0.0221, "dtheta_mean_deg": 0.225, "dtheta_std_deg": 0.179},
}
#: the project's target for the paper's own measurement: errors this many times below the paper's
TARGET_FACTOR = 4.0
#: the target of the felt error (true finger against true sheet): this many times below the paper's
FELT_TARGET_FACTOR = 2.0
#: one line for every report that prints Δd (module doc)
DD_CONVENTION = ("Δθ is the headline. Δd on R: |DD′| = chord ≈ R·Δθ (ours); Δd 2R: 2R·Δθ, the paper's "
                 "convention (its rows have Δd/Δθ = 70.7 mm/rad = the cylinder's diameter).")


def paper_dd_ratio(key: str = "10") -> float:
    """The paper's Δd/Δθ of row ``key``, mm/rad (70.7 for both rows: 2R, the cylinder's diameter)."""
    p = PAPER_TABLE1[key]
    return p["dd_mean_mm"] / math.radians(p["dtheta_mean_deg"])


def target(key: str = "10", factor: float = TARGET_FACTOR) -> dict[str, float]:
    """Target row: the paper's Δd and Δθ means of row ``key`` divided by ``factor`` (default
    :data:`TARGET_FACTOR`; the felt error's is :data:`FELT_TARGET_FACTOR`) (``dd_mean_mm``,
    ``dtheta_mean_deg``). Raises ``KeyError`` for a row the paper does not have."""
    p = PAPER_TABLE1[key]
    return {"dd_mean_mm": p["dd_mean_mm"] / factor, "dtheta_mean_deg": p["dtheta_mean_deg"] / factor}


@dataclass(frozen=True)
class StrokeErrors:
    """Per-sample errors: ``dd`` (N,) m, ``dtheta`` (N,) rad, ``gap`` (N,) m; ``D``, ``Dp`` (N, 3) m."""

    dd: np.ndarray
    dtheta: np.ndarray
    gap: np.ndarray
    D: np.ndarray
    Dp: np.ndarray


def _as_points(name: str, a, n: int | None = None) -> np.ndarray:
    a = np.asarray(a, dtype=float)
    if a.ndim != 2 or a.shape[1] != 3 or (n is not None and a.shape[0] != n):
        raise ValueError(f"{name} must have shape ({'N' if n is None else n}, 3), got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name} must be finite")
    return a


def stroke_errors(D, Dp, normals, normals_p) -> tuple[np.ndarray, np.ndarray]:
    """Δd (N,) m and Δθ (N,) rad from points D, D′ (N, 3) m and unit normals n(D), n′ (N, 3).

    Δd = |D − D′|; Δθ = atan2(|n × n′|, n·n′). Raises ``ValueError`` on mismatched shapes or non-finite data.
    """
    D = _as_points("D", D)
    N = D.shape[0]
    Dp = _as_points("Dp", Dp, N)
    n = _as_points("normals", normals, N)
    npp = _as_points("normals_p", normals_p, N)
    dd = np.linalg.norm(D - Dp, axis=1)
    dth = np.arctan2(np.linalg.norm(np.cross(n, npp), axis=1), np.sum(n * npp, axis=1))
    return dd, dth


def presented_contacts(shape: Shape, D, sheet_origin, sheet_normal) -> tuple[np.ndarray, np.ndarray]:
    """D′ (N, 3) m: where each actual sheet plane (origin (N, 3) m, unit normal (N, 3)) touches ``shape``,
    ties broken toward D (N, 3); and the gap (N,) m of D′ from the plane along the normal (> 0: floating)."""
    D = _as_points("D", D)
    N = D.shape[0]
    Org = _as_points("sheet_origin", sheet_origin, N)
    Nn = _as_points("sheet_normal", sheet_normal, N)
    Nu = Nn / np.linalg.norm(Nn, axis=1, keepdims=True)
    many = getattr(shape, "support_many", None)
    if many is not None:                     # a mesh: one batched closest-point query per iteration step
        Dp = many(Nu, D)
    else:
        Dp = np.array([shape.support(tuple(Nu[i]), tuple(D[i])) for i in range(N)], float).reshape(N, 3)
    gap = np.einsum("ij,ij->i", Org - Dp, Nu)
    return Dp, gap


def section_normals(shape: Shape, normals, ref_normals=None, tangents=None) -> np.ndarray:
    """Unit normals (N, 3) in the Fig. 9 cross-section (module doc). With ``ref_normals`` n(D) and
    ``tangents`` t (each (N, 3)): the component along the binormal b = n × t removed (the normal section along
    the stroke). Without: for a shape with an ``axis`` (the cylinder) the component along the axis removed,
    else just normalised. Raises ``ValueError`` on bad shapes/values, a normal along b (or the axis), or a
    tangent along n."""
    n = _as_points("sheet_normal", normals)
    if tangents is not None:
        N = n.shape[0]
        nr = _as_points("ref_normals", ref_normals, N)
        t = _as_points("tangents", tangents, N)
        t = t - np.einsum("ij,ij->i", t, nr)[:, None] * nr
        b = np.cross(nr, t)
        bl = np.linalg.norm(b, axis=1, keepdims=True)
        if np.any(bl < 1e-9):
            raise ValueError("tangents must not be along the reference normals")
        b /= bl
        n = n - np.einsum("ij,ij->i", n, b)[:, None] * b
    else:
        axis = getattr(shape, "axis", None)
        if axis is not None:
            a = np.asarray(axis, dtype=float)
            a = a / np.linalg.norm(a)
            n = n - np.outer(n @ a, a)
    nrm = np.linalg.norm(n, axis=1, keepdims=True)
    if np.any(nrm < 1e-9):
        raise ValueError("sheet_normal must be non-zero (and not along the section's binormal or the shape's "
                         "axis)")
    return n / nrm


def stroke_tangents(scene, D, samples: int = 513) -> np.ndarray:
    """Unit directions (N, 3) of ``scene``'s stroke path (:meth:`flexsheet.model.scenes.Scene.stroke_points`,
    ``samples`` points) at the path point nearest each D (N, 3) m: the t of the normal section along the
    stroke (module doc). Raises ``ValueError`` on bad shapes/values."""
    D = _as_points("D", D)
    P, _ = scene.stroke_points(int(samples))
    keep = np.concatenate([[True], np.linalg.norm(np.diff(P, axis=0), axis=1) > 1e-9])   # no repeated points
    P = P[keep]
    T = np.gradient(P, axis=0)
    T /= np.linalg.norm(T, axis=1, keepdims=True)
    d2 = ((D[:, None, :] - P[None, :, :]) ** 2).sum(-1)
    return T[np.argmin(d2, axis=1)]


def table1(shape: Shape, measured, sheet_origin, sheet_normal, scene=None) -> StrokeErrors:
    """Fig. 9 errors from time series: ``measured`` fingertip positions (N, 3) m and the actual sheet
    ``sheet_origin`` (N, 3) m and ``sheet_normal`` (N, 3) at the same instants (e.g. from ``/fingertip``
    and ``/world/sheet`` or the arms' FK). The sheet normals are taken in the cross-section
    (:func:`section_normals`): the normal section along ``scene``'s stroke (a
    :class:`flexsheet.model.scenes.Scene`, :func:`stroke_tangents`) when given, else the shape's axis
    section. Returns :class:`StrokeErrors`. Raises ``ValueError`` on bad shapes/values."""
    M = _as_points("measured", measured)
    N = M.shape[0]
    D = np.empty((N, 3))
    nD = np.empty((N, 3))
    hint = None
    if not shape.convex and hasattr(shape, "closest_many"):   # a mesh: its projection is the closest point
        D, nD, _ = shape.closest_many(M)
    else:
        for i in range(N):
            pr = shape.project(tuple(M[i]), hint)
            D[i], nD[i] = pr.point, pr.normal
            hint = pr.normal
    tang = stroke_tangents(scene, D) if scene is not None else None
    nS = section_normals(shape, _as_points("sheet_normal", sheet_normal, N), nD if tang is not None else None,
                         tang)
    Dp, gap = presented_contacts(shape, D, sheet_origin, nS)
    dd, dth = stroke_errors(D, Dp, nD, nS)
    return StrokeErrors(dd, dth, gap, D, Dp)


def summarize(dd, dtheta, radius: float | None = None) -> dict[str, float]:
    """Table I row: ``dd_mean_mm``, ``dd_std_mm``, ``dtheta_mean_deg``, ``dtheta_std_deg`` (population std),
    plus ``dd_p95_mm``, ``dtheta_p95_deg``, the medians ``dd_median_mm``, ``dtheta_median_deg`` (robust to a
    stalled stretch of a run on a loaded machine, which the mean is not) and ``n``; with ``radius`` R (m) also
    the paper's convention ``dd_2r_mean_mm``, ``dd_2r_std_mm`` = 2R·Δθ (module doc). Inputs (N,) m and rad;
    raises ``ValueError`` if empty or the radius is not positive."""
    dd = np.asarray(dd, dtype=float)
    dth = np.asarray(dtheta, dtype=float)
    if dd.size == 0 or dd.shape != dth.shape:
        raise ValueError(f"dd and dtheta must be non-empty and the same shape, got {dd.shape} and "
                         f"{dth.shape}")
    d = math.degrees(1.0)
    row = {"dd_mean_mm": float(dd.mean() * 1e3), "dd_std_mm": float(dd.std() * 1e3),
           "dtheta_mean_deg": float(dth.mean() * d), "dtheta_std_deg": float(dth.std() * d),
           "dd_p95_mm": float(np.percentile(dd, 95) * 1e3),
           "dtheta_p95_deg": float(np.percentile(dth, 95) * d),
           "dd_median_mm": float(np.median(dd) * 1e3), "dtheta_median_deg": float(np.median(dth) * d),
           "n": int(dd.size)}
    if radius is not None:
        if not (math.isfinite(radius) and radius > 0.0):
            raise ValueError(f"radius must be finite and > 0 m, got {radius!r}")
        row["dd_2r_mean_mm"] = float(2.0 * radius * dth.mean() * 1e3)
        row["dd_2r_std_mm"] = float(2.0 * radius * dth.std() * 1e3)
    return row


def table1_row(shape: Shape, measured, sheet_origin, sheet_normal, scene=None) -> dict[str, float]:
    """One Table I row from time series (see :func:`table1`; ``scene``: the section along its stroke):
    :func:`summarize` of Δd, Δθ (with the paper's 2R convention when the shape has a radius ``R``: the
    cylinder, the sphere) plus ``gap_mean_mm`` (mean |gap|, mm). The one metric of the in-process experiment
    and of a recorded run. Raises ``ValueError`` on bad shapes/values or no samples."""
    return errors_row(shape, table1(shape, measured, sheet_origin, sheet_normal, scene))


def errors_row(shape: Shape, err: StrokeErrors) -> dict[str, float]:
    """The row of :func:`table1_row` from errors already computed (:func:`table1`): :func:`summarize` (with
    the 2R convention when ``shape`` has a radius ``R``) plus ``gap_mean_mm``."""
    radius = getattr(shape, "R", None)
    row = summarize(err.dd, err.dtheta, float(radius) if isinstance(radius, (int, float)) else None)
    row["gap_mean_mm"] = float(np.mean(np.abs(err.gap)) * 1e3)
    return row


def scene_table1_row(scene, measured, sheet_origin, sheet_normal) -> dict[str, float]:
    """:func:`table1_row` on a :class:`flexsheet.model.scenes.Scene`: its shape as the planner sees it
    (:func:`flexsheet.planning.shape.planner_shape`: smooth normals on meshes) and the normal section along
    its stroke. For the paper's cylinder this gives the cylinder's Fig. 9 numbers."""
    return table1_row(planner_shape(scene), measured, sheet_origin, sheet_normal, scene)


#: the truth's modes whose moving phase is a Table I stroke
STROKE_MODES = ("stroke", "stroke_push")


def segment_key(truth) -> str:
    """The Table I row key of a truth sample's segment: ``"10"`` for "stroke", ``"stroke_push_10"``."""
    mt = f"{truth.moving_time:g}"
    return mt if truth.mode == "stroke" else f"{truth.mode}_{mt}"
