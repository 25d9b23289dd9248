"""What the object asks the finger to feel: its force–depth along the finger's normal at points on its stroke,
taken from the FEM model that deforms its image (one model of the object for sight and touch), and the mapping
of that force into what the sheet can present (pure; no FEM here: :mod:`flexsheet.fem.force_depth` builds the
table).

**Table.** ``points`` (P, 3) m on the undeformed surface along the scene's stroke (display frame), their
outward ``normals`` (P, 3), ``names`` (P,) (the stroke's start is ``reference``), ``depths`` (D,) m ascending
from 0 and ``force`` (P, D) N: the FEM's contact force for a fingertip pushed ``depth`` along −normal at the
point, the finger's contact law as the scene's.

**Look-up** (:meth:`ForceDepth.force`): the contact point is projected onto the polyline of the points; the
force is linear between the two neighbouring points and between depths; past the deepest depth it is
extrapolated with the last slope. Far off the stroke (:data:`REACH`) the nearest point's curve is used.

**Mapping** (:meth:`ForceDepth.mapped`): the force the sheet is asked for at depth d is F_req =
s·F_ref(d)·(F(q, d)/F_ref(d))^γ, where F_ref(d) is the median of the table's points at d (the body around any
inclusion), ``s`` one scale per scene and γ (``contrast_gain``) 1 for a faithful mapping; γ > 1 raises every
point's contrast against the body and keeps their order. The stiffness is its derivative in d (central
difference of the mapped force).

**Scale** (:func:`scene_scale`): the geometric centre of [s_lo, s_hi], the scales that keep every mapped force
(points × depths in [``d_min``, ``d_max``]) between what the sheet presents at its least stretch and at its
largest (a callable of the depth); when s_lo > s_hi no scale fits and the share that saturates is reported.

Units: m, N, N/m; display frame. Errors: ``ValueError`` naming the field and value.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from flexsheet.model.checks import check_positive

__all__ = ["REACH", "ForceDepth", "SceneScale", "scene_scale"]

#: a contact farther than this (m) from the stroke's polyline still takes
#: the nearest point's curve (reported by :meth:`ForceDepth.locate`)
REACH = 0.01


@dataclass(frozen=True)
class ForceDepth:
    """The object's force–depth table (module doc). Raises ``ValueError`` for inconsistent shapes, fewer than
    two points or depths, depths not ascending from 0, or negative / non-finite forces."""

    points: np.ndarray
    normals: np.ndarray
    names: tuple[str, ...]
    depths: np.ndarray
    force: np.ndarray
    scene_key: str = ""

    def __post_init__(self) -> None:
        P = np.asarray(self.points, float)
        N = np.asarray(self.normals, float)
        d = np.asarray(self.depths, float)
        F = np.asarray(self.force, float)
        if P.ndim != 2 or P.shape[1] != 3 or len(P) < 2:
            raise ValueError(f"points must be (P >= 2, 3) m, got shape {P.shape}")
        if N.shape != P.shape:
            raise ValueError(f"normals must have the points' shape {P.shape}, got {N.shape}")
        if len(self.names) != len(P):
            raise ValueError(f"names must name every point ({len(P)}), got {len(self.names)}")
        if d.ndim != 1 or len(d) < 2 or abs(d[0]) > 1e-12 or (np.diff(d) <= 0).any():
            raise ValueError(f"depths must ascend from 0 m, got {np.round(d, 6).tolist()[:8]}")
        if F.shape != (len(P), len(d)):
            raise ValueError(f"force must be (points, depths) = {(len(P), len(d))}, got {F.shape}")
        if not (np.isfinite(P).all() and np.isfinite(N).all() and np.isfinite(F).all()
                and F.min() >= 0.0):
            raise ValueError("points, normals and force must be finite, force >= 0 N")
        object.__setattr__(self, "points", P)
        object.__setattr__(self, "normals", N / np.linalg.norm(N, axis=1, keepdims=True))
        object.__setattr__(self, "depths", d)
        object.__setattr__(self, "force", F)
        object.__setattr__(self, "names", tuple(str(n) for n in self.names))
        object.__setattr__(self, "_ref", np.median(F, axis=0))

    def locate(self, q) -> tuple[int, float, float]:
        """(segment i, weight a ∈ [0, 1] of point i + 1, distance m) of contact ``q`` (3,) m projected onto
        the polyline of the points. Raises ``ValueError`` for a non-finite or mis-shaped ``q``."""
        qv = np.asarray(q, float)
        if qv.shape != (3,) or not np.isfinite(qv).all():
            raise ValueError(f"contact point must be finite (3,) m, got {q!r}")
        A, B = self.points[:-1], self.points[1:]
        AB = B - A
        L2 = np.maximum(np.einsum("ij,ij->i", AB, AB), 1e-30)
        a = np.clip(np.einsum("ij,ij->i", qv - A, AB) / L2, 0.0, 1.0)
        dist = np.linalg.norm(A + a[:, None] * AB - qv, axis=1)
        i = int(np.argmin(dist))
        return i, float(a[i]), float(dist[i])

    def _at_depth(self, row: np.ndarray, depth: float) -> float:
        d = self.depths
        if depth <= d[-1]:
            return float(np.interp(depth, d, row))
        slope = (row[-1] - row[-2]) / (d[-1] - d[-2])
        return float(row[-1] + slope * (depth - d[-1]))

    def force_at(self, q, depth: float) -> float:
        """The object's force (N) for a finger ``depth`` m (≥ 0) deep at contact ``q`` (3,) m (module doc).
        Raises ``ValueError`` for a negative or non-finite depth or a bad ``q``."""
        if not (math.isfinite(depth) and depth >= 0.0):
            raise ValueError(f"depth must be finite and >= 0 m, got {depth!r}")
        i, a, _ = self.locate(q)
        row = (1.0 - a) * self.force[i] + a * self.force[i + 1]
        return max(0.0, self._at_depth(row, depth))

    def reference_force(self, depth: float) -> float:
        """F_ref(d) N: the median of the points' forces at ``depth`` m (module doc)."""
        return max(0.0, self._at_depth(self._ref, depth))

    def mapped(self, q, depth: float, scale: float, gain: float = 1.0) -> tuple[float, float]:
        """(force N, stiffness N/m) the sheet is asked for at contact ``q`` (3,) m, ``depth`` m, with the
        scene's ``scale`` s > 0 and ``gain`` γ > 0 (module doc). Raises ``ValueError`` for a bad input."""
        scale, gain = check_positive("scale", scale), check_positive("contrast_gain", gain)
        h = 5e-4

        def f(d: float) -> float:
            F = self.force_at(q, d)
            if gain == 1.0:
                return scale * F
            ref = self.reference_force(d)
            return scale * ref * (F / ref) ** gain if ref > 0.0 and F > 0.0 else scale * F

        lo = max(0.0, depth - h)
        hi = depth + h
        return f(depth), max(0.0, (f(hi) - f(lo)) / (hi - lo))

    def to_json(self) -> dict:
        """``{"points": [{"name", "position_m", "normal", "depth_m", "force_n"}], "scene_key"}``."""
        return {"scene_key": self.scene_key,
                "points": [{"name": n, "position_m": p.tolist(), "normal": nv.tolist(),
                            "depth_m": self.depths.tolist(), "force_n": f.tolist()}
                           for n, p, nv,
                           f in zip(self.names, self.points, self.normals, self.force, strict=True)]}

    @classmethod
    def from_json(cls, d: dict) -> ForceDepth:
        """Inverse of :meth:`to_json` (every point on the same depths). Raises ``ValueError`` naming the
        field."""
        try:
            pts = d["points"]
            depths = np.asarray(pts[0]["depth_m"], float)
            for p in pts:
                if not np.array_equal(np.asarray(p["depth_m"], float), depths):
                    raise ValueError(f"force_depth: point {p.get('name')!r} has other depths than the first")
            return cls(np.array([p["position_m"] for p in pts], float),
                       np.array([p["normal"] for p in pts], float),
                       tuple(p["name"] for p in pts), depths, np.array([p["force_n"] for p in pts], float),
                       str(d.get("scene_key", "")))
        except (KeyError, IndexError, TypeError) as exc:
            raise ValueError(f"force_depth: malformed table ({type(exc).__name__}: {exc})") from None


@dataclass(frozen=True)
class SceneScale:
    """:func:`scene_scale`'s answer: ``scale`` s; ``low`` s_lo and ``high`` s_hi (the scales at which the
    softest / stiffest mapped sample meets the sheet's floor / ceiling); ``fits`` s_lo ≤ s_hi; ``saturated``
    the share of table samples outside the presentable range at ``scale``."""

    scale: float
    low: float
    high: float
    fits: bool
    saturated: float


def scene_scale(table: ForceDepth, floor: Callable[[float], float], ceiling: Callable[[float], float],
                d_min: float, d_max: float, gain: float = 1.0) -> SceneScale:
    """One scale for the scene (module doc): ``floor(d)`` / ``ceiling(d)`` the sheet's force (N) at depth d at
    its least and largest stretch; samples at the table's depths within [``d_min``, ``d_max``] m (at least
    one). Raises ``ValueError`` when no depth lies in the range or a bound is not positive."""
    ds = [float(d) for d in table.depths if d_min - 1e-12 <= d <= d_max + 1e-12]
    if not ds:
        raise ValueError(f"no table depth within [{d_min!r}, {d_max!r}] m")
    lo, hi, req, lims = 0.0, math.inf, [], []
    for d in ds:
        fl, ce = float(floor(d)), float(ceiling(d))
        if not (fl > 0.0 and ce > fl):
            raise ValueError(f"sheet force at {d * 1e3:.1f} mm must satisfy 0 < floor < ceiling, got {fl!r}, "
                             f"{ce!r}")
        for p in table.points:
            F = table.mapped(p, d, 1.0, gain)[0]
            if F <= 0.0:
                continue
            lo, hi = max(lo, fl / F), min(hi, ce / F)
            req.append(F)
            lims.append((fl, ce))
    s = math.sqrt(lo * hi) if lo > 0.0 and math.isfinite(hi) else (hi if math.isfinite(hi) else 1.0)
    sat = (float(np.mean([not (fl <= s * F <= ce) for F, (fl, ce) in zip(req, lims, strict=True)])) if req
           else 0.0)
    return SceneScale(s, lo, hi, lo <= hi, sat)
