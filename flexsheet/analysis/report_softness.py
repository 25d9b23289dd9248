"""What the finger feels against what the object asks, from a run's bag (pure; no transport).

The world publishes the finger's true contact with the true sheet (``/world/contact``, ``ContactTruth``: depth
and force, N, from the truth's sheet FEM table at the true depth, never a model of the planner's). What the
object asks at that contact and depth is its force–depth table from its own FEM (``/object/force_depth``,
:class:`flexsheet.model.force_depth.ForceDepth`) mapped as the planner maps it (``stiffness_scale`` and
``contrast_gain`` in force, from the planner's heartbeats): the request at the *true* depth, so the finger's
tracking lag and the object's sticking contact (which drags its surface along a sliding finger) do not enter.
A bag without the table (recorded before it existed) pairs the FEM node's ``ObjectDeformation.contact_force`` at
the display's measured fingertip instead. Their ratio, sample by sample while the finger presses, is the
presented softness error a person could notice: a force-at-depth difference under the Weber fraction of about
15 % goes unnoticed (Bergmann Tiest & Kappers, IEEE Trans. Haptics 2:189, 2009, with the surface-deformation
cue present).

Units: N, m, N/m; stamps s.
"""

from __future__ import annotations

import numpy as np

from flexsheet.analysis.report_timing import planner_gains, planner_scales, scales_at
from flexsheet.model.force_depth import ForceDepth

__all__ = ["WEBER_FRACTION", "MIN_DEPTH", "WITHIN_TARGET", "STRAIN_LIMIT", "felt_force", "follow_lag", "force_depth_table", "inclusion_contrast", "sheet_summary"]

#: a force or stiffness ratio within 1 ± this goes unnoticed (Bergmann Tiest & Kappers 2009)
WEBER_FRACTION = 0.15
#: pushes shallower than this (m) are not judged: the fingertip grazes the sheet, and a force of a few mN
#: divides into a meaningless ratio
MIN_DEPTH = 0.002
#: an object force sample is paired with a sheet sample at most this long (s) after its fingertip's exposure
MAX_GAP = 0.1
#: the share of pressed samples within the Weber fraction a run must reach
WITHIN_TARGET = 0.95


def force_depth_table(d: dict[str, list]):
    """The newest ``/object/force_depth`` in ``d`` as a :class:`~flexsheet.model.force_depth.ForceDepth`, or None."""
    msgs = [m for _, m in d.get("/object/force_depth", []) if m is not None]
    if not msgs:
        return None
    m = msgs[-1]
    return ForceDepth(m.points, m.normals, tuple(m.names), m.depths, m.force, m.scene_key)


def _pressed(d: dict[str, list]) -> list:
    """The ``/world/contact`` samples pressed at least :data:`MIN_DEPTH` deep with a force, in log order."""
    return [(t, m) for t, m in d.get("/world/contact", []) if m.depth >= MIN_DEPTH and m.force > 0.0]


def felt_force(d: dict[str, list], scales: list[tuple[float, float]] | None = None) -> dict:
    """Compare each ``/world/contact`` sample pressed at least :data:`MIN_DEPTH` deep with what the object asks
    there (module doc): with ``/object/force_depth``, the table's mapped force at the true contact point and
    depth (``"basis": "force_depth"``); without, the newest ``/object/deformation`` whose fingertip was exposed at
    most :data:`MAX_GAP` s before it, times the scale (``"basis": "deformation"``). ``scales`` [(arrival s,
    scale)] (None: from the planner's heartbeats in ``d``, :func:`~flexsheet.analysis.report_timing.planner_scales`;
    1 without any); the contrast gain likewise (:func:`~flexsheet.analysis.report_timing.planner_gains`).

    ``d``: topic → [(log time, message)]. Returns ``{}`` without pressed samples, else ``{"n", "basis", "ratio"``
    (felt / requested: median, p5, p95), ``"within_15pct"`` (share with |ratio − 1| ≤ 15 %), ``"felt_n"`` and
    ``"requested_n"`` (force medians, N), ``"felt_stiffness_n_per_m"`` (median secant force / depth of the true
    sheet), ``"samples"`` {depth_m, felt_n, requested_n} (for the chart), ``"target"``, ``"verdict"`` ("met"
    when within_15pct ≥ :data:`WITHIN_TARGET`)}``. Raises ``ValueError`` for a non-positive scale."""
    scales = planner_scales(d) if scales is None else list(scales)
    bad = [s for _, s in scales if not s > 0.0]
    if bad:
        raise ValueError(f"stiffness scale must be > 0, got {bad[0]!r}")
    pressed = _pressed(d)
    if not pressed:
        return {}
    arrival = np.array([t for t, _ in pressed])
    scale = np.nan_to_num(scales_at(scales, arrival), nan=1.0)
    table = force_depth_table(d)
    felt, req, depth = [], [], []
    if table is not None:
        gains = np.nan_to_num(scales_at(planner_gains(d), arrival), nan=1.0)
        for (_, s), sc, g in zip(pressed, scale, gains, strict=True):
            felt.append(s.force)
            req.append(table.mapped(s.point, s.depth, float(sc), float(g))[0])
            depth.append(s.depth)
        basis = "force_depth"
    else:
        defs = sorted((m for _, m in d.get("/object/deformation", []) if m.contact_force > 0.0),
                      key=lambda m: m.source_stamp)
        if not defs:
            return {}
        ds = np.array([m.source_stamp for m in defs])
        for (_, s), sc in zip(pressed, scale, strict=True):
            k = int(np.searchsorted(ds, s.header.stamp, side="right")) - 1
            if k < 0 or s.header.stamp - ds[k] > MAX_GAP:
                continue
            felt.append(s.force)
            req.append(defs[k].contact_force * float(sc))
            depth.append(s.depth)
        basis = "deformation"
    ok = [i for i, r in enumerate(req) if r > 0.0]
    if not ok:
        return {}
    felt_a, req_a, dep_a = (np.array([x[i] for i in ok]) for x in (felt, req, depth))
    ratio = felt_a / req_a
    within = float(np.mean(np.abs(ratio - 1.0) <= WEBER_FRACTION))
    return {"n": len(ok), "basis": basis,
            "ratio": {"median": float(np.median(ratio)), "p5": float(np.percentile(ratio, 5)),
                      "p95": float(np.percentile(ratio, 95))},
            "within_15pct": within,
            "felt_n": float(np.median(felt_a)), "requested_n": float(np.median(req_a)),
            "felt_stiffness_n_per_m": float(np.median(felt_a / dep_a)),
            "samples": {"depth_m": dep_a.tolist(), "felt_n": felt_a.tolist(), "requested_n": req_a.tolist()},
            "target": f">= {WITHIN_TARGET:.2f} of pressed samples (>= {MIN_DEPTH * 1e3:g} mm) with the true force within "
                      f"± {100 * WEBER_FRACTION:.0f} % of the mapped request (Weber fraction, Bergmann Tiest & Kappers 2009)",
            "verdict": "met" if within >= WITHIN_TARGET else "MISSED"}


#: the urethane sheet's working strain (Treloar 1975 neo-Hookean range, docs/planner.md)
STRAIN_LIMIT = 0.30
#: the true clamp strain may exceed the planned one by at most this
STRAIN_OVER_PLAN = 0.02


def sheet_summary(d: dict[str, list]) -> dict:
    """The true sheet against the plan, from a bag: ``strain_true_max`` (``/world/sheet`` stretch),
    ``strain_over_plan_max`` (true minus the newest ``/sheet/target`` stretch planned before it), and
    ``one_arm_holds``: joint-state cycles of one bridge holding (``bridge_status`` "hold…"; not "hold:no_target",
    a bridge before its first target) while the other's newest state does not; with ``targets`` and ``verdict`` (strain ≤ :data:`STRAIN_LIMIT`, ≤ :data:`STRAIN_OVER_PLAN`
    over the plan, no one-arm hold). ``{}`` without ``/world/sheet``."""
    world = [m for _, m in d.get("/world/sheet", [])]
    if not world:
        return {}
    true = np.array([m.stretch for m in world])
    tw = np.array([m.header.stamp for m in world])
    tg = [m for _, m in d.get("/sheet/target", [])]
    over = float("nan")
    if tg:
        tt = np.array([m.header.stamp for m in tg])
        k = np.searchsorted(tt, tw, side="right") - 1
        ok = k >= 0
        if ok.any():
            plan = np.array([tg[i].stretch for i in k[ok]])
            over = float(np.max(true[ok] - plan))
    states = sorted([(m.header.stamp, m.arm, m.bridge_status.startswith("hold") and m.bridge_status != "hold:no_target")
                     for topic in ("/arm/left/joint_state", "/arm/right/joint_state")
                     for _, m in d.get(topic, [])])
    last: dict[str, bool] = {}
    one = 0
    for i, (t, arm, held) in enumerate(states):
        last[arm] = held
        if i + 1 < len(states) and states[i + 1][0] == t:
            continue                        # judge a cycle once both arms' states of the same stamp are in
        if len(last) == 2 and last["left"] != last["right"]:
            one += 1
    met = float(true.max()) <= STRAIN_LIMIT and not (over > STRAIN_OVER_PLAN) and one == 0
    return {"strain_true_max": float(true.max()), "strain_over_plan_max": over, "one_arm_holds": one,
            "targets": {"strain_true_max": STRAIN_LIMIT, "strain_over_plan_max": STRAIN_OVER_PLAN, "one_arm_holds": 0},
            "verdict": "met" if met else "MISSED"}


def inclusion_contrast(d: dict[str, list], scene, scales=None) -> dict:
    """The inclusion's contrast a finger felt, from true forces at matched depth: pressed ``/world/contact``
    samples (≥ :data:`MIN_DEPTH`) over the inclusion's footprint (the contact point within the inclusion's radius
    of the point on the surface above its centre) against those around it (beyond 2 radii), in 1 mm depth bins
    holding both; per bin the median force over, over the median around, less 1; the median over bins. The
    requested contrast is the object's own (its force–depth table at the same samples, unmapped), the presented
    request's the mapped one. ``{}`` without a scene inclusion, the table, or a bin with both.
    Returns ``{"felt", "requested", "mapped", "bins", "n_over", "n_around"}``."""
    table = force_depth_table(d)
    incs = list(getattr(scene, "inclusions", []) or []) if scene is not None else []
    if table is None or not incs:
        return {}
    inc = incs[0]
    c, r = np.asarray(inc.center, float), float(inc.radius)
    top = table.points[int(np.argmin(np.linalg.norm(table.points - c, axis=1)))]
    pressed = _pressed(d)
    if not pressed:
        return {}
    scales = planner_scales(d) if scales is None else scales
    arrival = np.array([t for t, _ in pressed])
    sc = np.nan_to_num(scales_at(scales, arrival), nan=1.0)
    gains = np.nan_to_num(scales_at(planner_gains(d), arrival), nan=1.0)
    rows = []
    for (_, m), s, g in zip(pressed, sc, gains, strict=True):
        dist = float(np.linalg.norm(np.asarray(m.point) - top))
        where = "over" if dist <= r else ("around" if dist >= 2 * r else None)
        if where is None:
            continue
        rows.append((where, m.depth, m.force, table.force_at(m.point, m.depth),
                     table.mapped(m.point, m.depth, float(s), float(g))[0]))
    bins = []
    for b in np.arange(MIN_DEPTH, max((x[1] for x in rows), default=0.0) + 1e-3, 1e-3):
        over = [x for x in rows if x[0] == "over" and b <= x[1] < b + 1e-3]
        around = [x for x in rows if x[0] == "around" and b <= x[1] < b + 1e-3]
        if len(over) >= 3 and len(around) >= 3:
            med = lambda xs, k: float(np.median([x[k] for x in xs]))     # noqa: E731
            bins.append({"depth_mm": 1e3 * (b + 5e-4), "felt": med(over, 2) / med(around, 2) - 1.0,
                         "requested": med(over, 3) / med(around, 3) - 1.0, "mapped": med(over, 4) / med(around, 4) - 1.0,
                         "n_over": len(over), "n_around": len(around)})
    if not bins:
        return {}
    return {"felt": float(np.median([b["felt"] for b in bins])),
            "requested": float(np.median([b["requested"] for b in bins])),
            "mapped": float(np.median([b["mapped"] for b in bins])), "bins": bins,
            "n_over": sum(b["n_over"] for b in bins), "n_around": sum(b["n_around"] for b in bins)}


#: the tension must follow the finger within this (ms)
FOLLOW_TARGET_MS = 60.0


def follow_lag(d: dict[str, list], window: float = 0.5) -> dict:
    """How late the true sheet's tension follows the finger: the delay τ (ms, 0–200 in 1 ms steps) at which the
    rate of the true clamp strain (``/world/sheet`` stretch) best correlates with the rate of the planned one as a
    function of the fingertip's exposure (``/sheet/target`` stretch at its ``source_stamp``, delayed by τ); both
    resampled at 2 ms, over the ``window`` s around every judged pressed sample (:func:`felt_force`'s). Rates, not
    values: the identified sheet's strain differs from the truth's by a near-constant offset, which made the fit on
    values flat. A stroke asks a ramp, not a step, so the delay is the figure: 90 % of a step is reached a rise
    time later. ``{}`` without samples. Returns ``{"follow_ms", "correlation", "n", "target_ms", "verdict"}``."""
    world = [m for _, m in d.get("/world/sheet", [])]
    tg = sorted((m for _, m in d.get("/sheet/target", []) if not m.status.startswith("hold")),
                key=lambda m: m.source_stamp)
    pressed = _pressed(d)
    if len(world) < 10 or len(tg) < 10 or not pressed:
        return {}
    tw = np.array([m.header.stamp for m in world])
    ew = np.array([m.stretch for m in world])
    ts = np.array([m.source_stamp for m in tg])
    ep = np.array([m.stretch for m in tg])
    g = np.arange(tw[0], tw[-1], 0.002)
    use = np.zeros(len(g), bool)
    for c in (m.header.stamp for _, m in pressed):
        lo, hi = np.searchsorted(g, [c - window, c + window])
        use[lo:hi] = True
    if use.sum() < 50:
        return {}
    rate_true = np.gradient(np.interp(g, tw, ew), g)[use]
    best, best_c = 0.0, -2.0
    for tau in np.arange(0.0, 0.2005, 0.001):
        rate_plan = np.gradient(np.interp(g - tau, ts, ep), g)[use]
        if rate_plan.std() == 0 or rate_true.std() == 0:
            continue
        c = float(np.corrcoef(rate_true, rate_plan)[0, 1])
        if c > best_c:
            best, best_c = float(tau), c
    if best_c <= -2.0:
        return {}
    ms = 1e3 * best
    return {"follow_ms": ms, "correlation": best_c, "n": int(use.sum()), "target_ms": FOLLOW_TARGET_MS,
            "verdict": "met" if ms <= FOLLOW_TARGET_MS else "MISSED"}
