"""How the two arms moved the sheet, from a run's bag (pure; no transport): the true clamp span against the
planned one, every sample, moves included, and the cycles the fallback guards acted.

The planned span at an instant is the sheet's motion both bridges were following then
(:class:`flexsheet.arm.sheet_motion.SheetSegment`, rebuilt from the newest ``/arm/left/target`` with a motion
before it; a segment that does not rebuild: its goal's strain), ``size·(1 + ε_plan(t))``; the true one is the world's
``size·(1 + ε_true)`` (``/world/sheet``, signed: negative when slack), both with the planned sheet's side.
The guards (the span guard's ``wait:span`` and the partner hold ``hold:peer``, :mod:`flexsheet.arm.tracking`) are
the fault fallback: in a normal run they never act.

Units: mm in the summary (labelled), s.
"""

from __future__ import annotations

import numpy as np

from flexsheet.arm.sheet_motion import MotionError, SheetSegment

__all__ = ["SPAN_ERROR_P99_MM", "motion_summary"]

#: the true clamp span may leave the planned one by at most this, p99, mm
SPAN_ERROR_P99_MM = 1.0
#: the bridge statuses of a guard acting
GUARD_STATUSES = ("wait:span", "hold:peer")


def _planned_strain(targets: list, stamps: np.ndarray) -> np.ndarray:
    """ε_plan (n,) at ``stamps`` (n,) s from the ``/arm/left/target`` messages (NaN before the first)."""
    out = np.full(len(stamps), np.nan)
    t0s = np.array([m.header.stamp for m in targets])
    k = np.searchsorted(t0s, stamps, side="right") - 1
    segs: dict[int, SheetSegment | None] = {}
    for i, j in enumerate(k):
        if j < 0:
            continue
        if j not in segs:
            try:
                segs[j] = SheetSegment.from_fields(targets[j])
            except MotionError:
                segs[j] = None
        seg, m = segs[j], targets[j]
        out[i] = seg.sheet(stamps[i])[2] if seg is not None else _goal_strain(m)
    return out


def _goal_strain(m) -> float:
    """The strain of a target's motion's goal (the segment itself did not rebuild), else NaN."""
    return float(m.motion[3, 6]) if m.motion_t0 is not None else float("nan")


def motion_summary(d: dict[str, list]) -> dict:
    """``span_error_mm`` {median, p99, max}: |true − planned| clamp span, mm, over every ``/world/sheet`` sample
    after the first target with a motion; ``guard_waits``: joint-state cycles of either bridge in a guard's
    status; with ``targets`` and ``verdict``. ``{}`` without ``/world/sheet`` or targets with a motion."""
    world = [m for _, m in d.get("/world/sheet", [])]
    targets = sorted((m for _, m in d.get("/arm/left/target", []) if m.motion_t0 is not None),
                     key=lambda m: m.header.stamp)
    waits = sum(m.bridge_status in GUARD_STATUSES
                for topic in ("/arm/left/joint_state", "/arm/right/joint_state") for _, m in d.get(topic, []))
    if not world or not targets:
        return {}
    tw = np.array([m.header.stamp for m in world])
    keep = tw >= targets[0].header.stamp
    size = float(targets[-1].motion_size)
    plan = _planned_strain(targets, tw[keep])
    true = np.array([m.stretch for m in world])[keep]
    ok = np.isfinite(plan)
    if not ok.any():
        return {}
    err = np.abs(true[ok] - plan[ok]) * size * 1e3
    span = {"median": float(np.median(err)), "p99": float(np.percentile(err, 99)), "max": float(err.max()),
            "n": int(ok.sum())}
    met = span["p99"] <= SPAN_ERROR_P99_MM and waits == 0
    return {"span_error_mm": span, "guard_waits": int(waits),
            "motion_targets": {"span_error_mm.p99": SPAN_ERROR_P99_MM, "guard_waits": 0},
            "motion_verdict": "met" if met else "MISSED"}
