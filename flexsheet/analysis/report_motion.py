"""How the two arms moved the sheet, from a run's bag (pure; no transport): the true clamp span against the
planned one, every sample, moves included, and the cycles the fallback guards acted.

The planned span at an instant is the sheet's motion both bridges were following then
(:class:`flexsheet.arm.sheet_motion.SheetSegment`, rebuilt from the newest ``/arm/left/target`` with a motion
before it; a segment that does not rebuild: its goal's strain), ``size·(1 + ε_plan(t))``; the true one is the
world's ``size·(1 + ε_true)`` (``/world/sheet``, signed: negative when slack), both with the planned sheet's
side. Each clamp's measured pose (``/arm/<side>/joint_state`` ``pose``: the bridge's forward kinematics of the
measured joints) is compared with the motion's clamp at the same instant (``path_dev_mm``), and each clamp's
lag behind the motion (the time shift that best lays the measured clamp on the planned clamp path) is compared
between the two arms while the sheet moves (``arrival_skew_ms``: how far apart in time the two clamps travel
the shared motion). The guards (the span guard's ``wait:span`` and the partner hold ``hold:peer``,
:mod:`flexsheet.arm.tracking`) are the fault fallback: in a normal run they never act.

Units: mm in the summary (labelled), s.
"""

from __future__ import annotations

import numpy as np

from flexsheet.arm.sheet_motion import MotionError, SheetSegment

__all__ = ["SPAN_ERROR_P99_MM", "motion_summary", "clamp_tracking"]

#: the true clamp span may leave the planned one by at most this, p99, mm
SPAN_ERROR_P99_MM = 1.0
#: the bridge statuses of a guard acting
GUARD_STATUSES = ("wait:span", "hold:peer")
#: the planned clamp path's sampling for the lag search, s;
#: the lags searched, s; "moving": planned clamp speed, m/s
LAG_GRID_S, LAG_RANGE_S, MOVING_MPS = 0.002, (-0.1, 0.4), 0.02


def _segments_at(targets: list, stamps: np.ndarray, cache: dict) -> tuple[np.ndarray, list]:
    """(k (n,): the index in ``targets`` of the newest ``/arm/left/target`` with a motion at or before each of
    ``stamps`` (n,) s, −1 before the first; the segment each follows, None before the first or where it does
    not rebuild). ``cache`` {index: segment}: segments rebuilt once per target across calls."""
    t0s = np.array([m.header.stamp for m in targets])
    k = np.searchsorted(t0s, stamps, side="right") - 1
    out = []
    for j in k:
        if j < 0:
            out.append(None)
            continue
        if j not in cache:
            try:
                cache[j] = SheetSegment.from_fields(targets[j])
            except MotionError:
                cache[j] = None
        out.append(cache[j])
    return k, out


def _planned_clamps(targets: list, stamps: np.ndarray, cache: dict) -> np.ndarray:
    """The motion's (left, right) clamp positions (n, 2, 3) m at ``stamps`` (n,) s, NaN where none is
    followed."""
    out = np.full((len(stamps), 2, 3), np.nan)
    for i, (t, seg) in enumerate(zip(stamps, _segments_at(targets, stamps, cache)[1], strict=True)):
        if seg is not None:
            out[i] = seg.clamp_points(float(t))
    return out


def clamp_tracking(d: dict[str, list], targets: list, cache: dict | None = None) -> dict:
    """``path_dev_mm`` {median, p99, max, n}: each arm's measured clamp against the motion's at the same
    stamp, mm; ``arrival_skew_ms`` {median, p99, max, n}: |lag_left − lag_right| while the planned clamps move
    faster than :data:`MOVING_MPS`, ms (each lag the shift in :data:`LAG_RANGE_S` that lays the measured clamp
    nearest the planned path, on a :data:`LAG_GRID_S` grid). ``{}`` without joint states after the first
    target. ``targets``: the ``/arm/left/target`` messages with a motion, by stamp; ``cache``: as
    :func:`_segments_at`."""
    start = targets[0].header.stamp
    meas = {}
    for i, side in enumerate(("left", "right")):
        js = [m for _, m in d.get(f"/arm/{side}/joint_state", []) if m.header.stamp >= start]
        if js:
            meas[side] = (i, np.array([m.header.stamp for m in js]), np.array([m.pose[:3, 3] for m in js]))
    if len(meas) < 2:
        return {}
    t_end = max(v[1][-1] for v in meas.values())
    grid = np.arange(start, t_end + LAG_GRID_S, LAG_GRID_S)
    path = _planned_clamps(targets, grid, {} if cache is None else cache)   # (G, 2, 3)
    lo, hi = (int(round(x / LAG_GRID_S)) for x in LAG_RANGE_S)
    dev, lags = [], {}
    for side, (i, ts, p) in meas.items():
        g = np.clip(np.round((ts - start) / LAG_GRID_S).astype(int), 0, len(grid) - 1)
        dev.append(np.linalg.norm(p - path[g, i], axis=1))
        shifts = np.arange(lo, hi + 1)
        idx = np.clip(g[:, None] - shifts[None, :], 0, len(grid) - 1)             # (n, L): planned at t − δ
        dist = np.linalg.norm(path[idx, i] - p[:, None, :], axis=2)
        dist[~np.isfinite(dist)] = np.inf
        lag = shifts[np.argmin(dist, axis=1)] * LAG_GRID_S
        speed = np.linalg.norm(path[np.minimum(g + 1, len(grid) - 1), i] - path[g, i], axis=1) / LAG_GRID_S
        ok = np.isfinite(dist).any(axis=1) & (speed > MOVING_MPS)
        lags[side] = (ts, lag, ok)
    dv = np.concatenate(dev)
    dv = dv[np.isfinite(dv)] * 1e3
    (tl, ll, okl), (tr, lr, okr) = lags["left"], lags["right"]
    both = okl & (np.interp(tl, tr, okr.astype(float)) > 0.999)
    skew = np.abs(ll - np.interp(tl, tr, lr))[both] * 1e3

    def stats(x) -> dict:
        return ({"median": float(np.median(x)), "p99": float(np.percentile(x, 99)), "max": float(x.max()),
                 "n": int(len(x))} if len(x) else {"median": None, "p99": None, "max": None, "n": 0})
    return {"path_dev_mm": stats(dv), "arrival_skew_ms": stats(skew)}


def _planned_strain(targets: list, stamps: np.ndarray, cache: dict) -> np.ndarray:
    """ε_plan (n,) at ``stamps`` (n,) s from the ``/arm/left/target`` messages (NaN before the first)."""
    out = np.full(len(stamps), np.nan)
    for i, (j, seg) in enumerate(zip(*_segments_at(targets, stamps, cache), strict=True)):
        if j >= 0:
            out[i] = seg.sheet(stamps[i])[2] if seg is not None else _goal_strain(targets[j])
    return out


def _goal_strain(m) -> float:
    """The strain of a target's motion's goal (the segment itself did not rebuild), else NaN."""
    return float(m.motion[3, 6]) if m.motion_t0 is not None else float("nan")


def motion_summary(d: dict[str, list]) -> dict:
    """``span_error_mm`` {median, p99, max}: |true − planned| clamp span, mm, over every ``/world/sheet``
    sample after the first target with a motion; ``guard_waits``: joint-state cycles of either bridge in a
    guard's status; with ``targets`` and ``verdict``. ``{}`` without ``/world/sheet`` or targets with a
    motion."""
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
    segments: dict = {}                       # one rebuild per target for the span and the clamps alike
    plan = _planned_strain(targets, tw[keep], segments)
    true = np.array([m.stretch for m in world])[keep]
    ok = np.isfinite(plan)
    if not ok.any():
        return {}
    err = np.abs(true[ok] - plan[ok]) * size * 1e3
    span = {"median": float(np.median(err)), "p99": float(np.percentile(err, 99)), "max": float(err.max()),
            "n": int(ok.sum())}
    met = span["p99"] <= SPAN_ERROR_P99_MM and waits == 0
    return {"span_error_mm": span, "guard_waits": int(waits), **clamp_tracking(d, targets, segments),
            "motion_targets": {"span_error_mm.p99": SPAN_ERROR_P99_MM, "guard_waits": 0},
            "motion_verdict": "met" if met else "MISSED"}
