"""What the finger feels against what the object asks, and where the sheet is when it feels it, from a run's
bag (pure; no transport).

The world publishes the finger's true contact with the true sheet (``/world/contact``, ``ContactTruth``: depth
and force, N, from the truth's sheet FEM table at the true depth, never a model of the planner's; ``point``,
the bottom of the dent, is the true fingertip). What the object asks at that contact and depth is its
force–depth table from its own FEM (``/object/force_depth``, :class:`flexsheet.model.force_depth.ForceDepth`)
mapped as the planner maps it (``stiffness_scale`` and ``contrast_gain`` in force, from the planner's
heartbeats): the request at the *true* sheet depth, so the finger's tracking lag and the object's sticking
contact (which drags its surface along a sliding finger) do not enter. The table is looked up at the contact
on the *surface* (:func:`surface_points`: the dent's bottom moved back out along the true sheet's normal by
the sheet's depth, the sheet's undented point under the finger), not at the dent's bottom: one indentation
below a rounded edge (R 8 mm) the bottom projects onto the wrong station of the table. A bag without the table
(recorded before it existed) pairs the FEM node's ``ObjectDeformation.contact_force`` at the display's
measured fingertip instead. Their ratio, sample by sample while the finger presses, is the presented softness
error a person could notice: a force-at-depth difference under the Weber fraction of about 15 % goes unnoticed
(Bergmann Tiest & Kappers, IEEE Trans. Haptics 2:189, 2009, with the surface-deformation cue present).

A sample is judged when the finger is :data:`MIN_DEPTH` into the *object* (its own indentation: the true
fingertip against the scene's surface, :func:`object_surface`) and touches the sheet with a force; without a
scene the sheet's depth gates instead. Where the sheet stands is judged apart
(:func:`flexsheet.analysis.report_placement.placement`).

Units: N, m, N/m; stamps s; mm / ms only in report values named so.
"""

from __future__ import annotations

import numpy as np

from flexsheet.analysis.report_timing import planner_gains, planner_scales, scales_at
from flexsheet.model.force_depth import ForceDepth
from flexsheet.planning.shape import planner_shape

__all__ = ["WEBER_FRACTION", "MIN_DEPTH", "MAX_GAP", "WITHIN_TARGET", "STRAIN_LIMIT", "felt_force",
           "follow_lag",
           "judged_contacts", "force_depth_table", "inclusion_contrast", "sheet_summary", "surface_points",
           "object_surface",
           "episodes"]

#: a force or stiffness ratio within 1 ± this goes unnoticed (Bergmann Tiest & Kappers 2009)
WEBER_FRACTION = 0.15
#: pushes shallower than this (m) into the object are not judged: the fingertip
#: grazes the surface, and a force of a few mN divides into a meaningless ratio
MIN_DEPTH = 0.002
#: an object force sample is paired with a sheet sample at most this long (s) after its fingertip's exposure;
#: samples further apart than this (s) belong to different touches (:func:`episodes`)
MAX_GAP = 0.1
#: the share of pressed samples within the Weber fraction a run must reach
WITHIN_TARGET = 0.95


def force_depth_table(d: dict[str, list]):
    """The newest ``/object/force_depth`` in ``d`` as a :class:`~flexsheet.model.force_depth.ForceDepth`, or
    None."""
    msgs = [m for _, m in d.get("/object/force_depth", []) if m is not None]
    if not msgs:
        return None
    m = msgs[-1]
    return ForceDepth(m.points, m.normals, tuple(m.names), m.depths, m.force, m.scene_key)


def object_surface(shape, points) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The object's surface under fingertips ``points`` (N, 3) m, display frame: (surface point q (N, 3) m,
    outward unit normal (N, 3), signed distance (N,) m, negative inside: minus the object's own indentation),
    by the planner's placement rule (:meth:`flexsheet.model.shape_base.Shape.project`: the centre ray for a
    convex shape, the closest point with smooth normals for a mesh). ``shape``:
    :func:`flexsheet.planning.shape.planner_shape`'s."""
    x = np.asarray(points, float).reshape(-1, 3)
    if not getattr(shape, "convex", True) and hasattr(shape, "closest_many"):
        return shape.closest_many(x)
    q, n, dist = np.empty_like(x), np.empty_like(x), np.empty(len(x))
    hint = None
    for i, p in enumerate(x):
        pr = shape.project(tuple(p), hint)
        q[i], n[i], dist[i] = pr.point, pr.normal, pr.distance
        hint = tuple(n[i])
    return q, n, dist


def surface_points(d: dict[str, list], contacts: list, table=None) -> np.ndarray:
    """The contact on the surface (N, 3) m, display frame, for ``/world/contact`` messages ``contacts`` (N):
    the dent's bottom (``point``, the true fingertip) moved back out by the sheet's ``depth`` along the true
    sheet's normal (the ``/world/sheet`` of the same stamp, else the nearest), i.e. the sheet's undented point
    under the finger. Without ``/world/sheet`` (no bag of a run lacks it; synthetic ones may): along
    ``table``'s (:class:`ForceDepth`) normal where the point projects (twice, from the point moved out), which
    over a curve tighter than the depth can keep the wrong station; without either, the dent's bottom."""
    p = np.array([m.point for m in contacts], float).reshape(-1, 3)
    depth = np.array([m.depth for m in contacts], float)
    sheets = sorted((m for _, m in d.get("/world/sheet", [])), key=lambda m: m.header.stamp)
    if sheets:
        ts = np.array([m.header.stamp for m in sheets])
        nrm = np.array([m.normal for m in sheets], float)
        t = np.array([m.header.stamp for m in contacts], float)
        k = np.clip(np.searchsorted(ts, t), 0, len(ts) - 1)
        km = np.clip(k - 1, 0, len(ts) - 1)
        k = np.where(np.abs(ts[km] - t) < np.abs(ts[k] - t), km, k)
        n = nrm[k] / np.linalg.norm(nrm[k], axis=1, keepdims=True)
        return p + depth[:, None] * n
    if table is None:
        return p
    out = p.copy()
    for _ in range(2):
        for j in range(len(p)):
            i, a, _ = table.locate(out[j])
            n = (1.0 - a) * table.normals[i] + a * table.normals[i + 1]
            out[j] = p[j] + depth[j] * n / np.linalg.norm(n)
    return out


def episodes(stamps, on, gap: float = MAX_GAP) -> list[tuple[int, int]]:
    """Contiguous runs [start, stop) of ``on`` (N,) bool over time-sorted ``stamps`` (N,) s, a run broken by
    an off sample or a step longer than ``gap`` s: one touch (or press) each."""
    t, on = np.asarray(stamps, float), np.asarray(on, bool)
    out, start = [], None
    for i in range(len(t)):
        if start is not None and (not on[i] or t[i] - t[i - 1] > gap):
            out.append((start, i))
            start = None
        if on[i] and start is None:
            start = i
    if start is not None:
        out.append((start, len(t)))
    return out


def _pressed(d: dict[str, list], scene=None, table=None) -> list:
    """The judged ``/world/contact`` samples, in stamp order: dicts ``{"t"`` (log time s), ``"m"`` (the
    message), ``"q"`` (:func:`surface_points`), ``"object_depth"`` (m, None without a scene), ``"press"``
    (index of its contiguous touching run)}``. Judged: touching with a force and :data:`MIN_DEPTH` deep into
    the object (with ``scene``), else into the sheet."""
    contacts = sorted(d.get("/world/contact", []), key=lambda tm: tm[1].header.stamp)
    if not contacts:
        return []
    msgs = [m for _, m in contacts]
    touch = np.array([m.touching and m.force > 0.0 for m in msgs])
    press = np.full(len(msgs), -1)
    for j, (a, b) in enumerate(episodes([m.header.stamp for m in msgs], touch)):
        press[a:b] = j
    idx = np.flatnonzero(touch)
    if not idx.size:
        return []
    sel = [msgs[i] for i in idx]
    q = surface_points(d, sel, table)
    obj = None
    if scene is not None:
        obj = -object_surface(planner_shape(scene), np.array([m.point for m in sel], float))[2]
    out = []
    for j, i in enumerate(idx):
        deep = obj[j] if obj is not None else msgs[i].depth
        if deep >= MIN_DEPTH:
            out.append({"t": contacts[i][0], "m": msgs[i], "q": q[j],
                        "object_depth": None if obj is None else float(obj[j]), "press": int(press[i])})
    return out


def _per_press(press: np.ndarray, ratio: np.ndarray) -> dict:
    """Each press's median felt/requested ratio over its judged samples: ``{"n", "within_15pct"`` (share of
    presses within the Weber fraction), ``"ratio_median"`` (median over presses), ``"worst"`` (the press ratio
    farthest from 1), ``"ratios"`` (per press, in time order)}``."""
    meds = np.array([float(np.median(ratio[press == p])) for p in np.unique(press)])
    worst = float(meds[np.argmax(np.abs(meds - 1.0))])
    return {"n": int(len(meds)), "within_15pct": float(np.mean(np.abs(meds - 1.0) <= WEBER_FRACTION)),
            "ratio_median": float(np.median(meds)), "worst": worst, "ratios": meds.tolist()}


def felt_force(d: dict[str, list], scales: list[tuple[float, float]] | None = None, scene=None) -> dict:
    """Compare each judged ``/world/contact`` sample (:func:`_pressed`: touching with a force and at least
    :data:`MIN_DEPTH` into the object of ``scene``, a :class:`flexsheet.model.scenes.Scene`; None: into the
    sheet) with what the object asks there (module doc): with ``/object/force_depth``, the table's mapped
    force at the contact on the surface (:func:`surface_points`) and the true sheet depth
    (``"basis": "force_depth"``); without, the newest ``/object/deformation`` whose fingertip was exposed at
    most :data:`MAX_GAP` s before it, times the scale (``"basis": "deformation"``). ``scales`` [(arrival s,
    scale)] (None: from the planner's heartbeats in ``d``,
    :func:`~flexsheet.analysis.report_timing.planner_scales`; 1 without any); the contrast gain likewise
    (:func:`~flexsheet.analysis.report_timing.planner_gains`).

    ``d``: topic → [(log time, message)]. Returns ``{}`` without judged samples, else
    ``{"n", "basis", "gate"`` ("object_depth" or "sheet_depth"), ``"ratio"`` (felt / requested per sample:
    median, p5, p95), ``"within_15pct"`` (share of samples with |ratio − 1| ≤ 15 %; since the surface look-up
    and the object-depth gate, judged on those samples), ``"per_press"`` (:func:`_per_press`: one median ratio
    per contiguous touch), ``"felt_n"`` and ``"requested_n"`` (force medians, N), ``"felt_stiffness_n_per_m"``
    (median secant force / depth of the true sheet), ``"samples"`` {depth_m, felt_n, requested_n, stamp_s}
    (for the chart and the split by the planner's status), ``"target"``, ``"verdict"`` ("met" when
    within_15pct ≥ :data:`WITHIN_TARGET`)}``. Raises ``ValueError`` for a non-positive scale."""
    scales = planner_scales(d) if scales is None else list(scales)
    bad = [s for _, s in scales if not s > 0.0]
    if bad:
        raise ValueError(f"stiffness scale must be > 0, got {bad[0]!r}")
    table = force_depth_table(d)
    pressed = _pressed(d, scene, table)
    if not pressed:
        return {}
    arrival = np.array([r["t"] for r in pressed])
    scale = np.nan_to_num(scales_at(scales, arrival), nan=1.0)
    felt, req, depth, press, stamp = [], [], [], [], []
    if table is not None:
        gains = np.nan_to_num(scales_at(planner_gains(d), arrival), nan=1.0)
        for r, sc, g in zip(pressed, scale, gains, strict=True):
            s = r["m"]
            felt.append(s.force)
            req.append(table.mapped(r["q"], s.depth, float(sc), float(g))[0])
            depth.append(s.depth)
            press.append(r["press"])
            stamp.append(s.header.stamp)
        basis = "force_depth"
    else:
        defs = sorted((m for _, m in d.get("/object/deformation", []) if m.contact_force > 0.0),
                      key=lambda m: m.source_stamp)
        if not defs:
            return {}
        ds = np.array([m.source_stamp for m in defs])
        for r, sc in zip(pressed, scale, strict=True):
            s = r["m"]
            k = int(np.searchsorted(ds, s.header.stamp, side="right")) - 1
            if k < 0 or s.header.stamp - ds[k] > MAX_GAP:
                continue
            felt.append(s.force)
            req.append(defs[k].contact_force * float(sc))
            depth.append(s.depth)
            press.append(r["press"])
            stamp.append(s.header.stamp)
        basis = "deformation"
    ok = [i for i, r in enumerate(req) if r > 0.0]
    if not ok:
        return {}
    felt_a, req_a, dep_a, press_a, st_a = (np.array([x[i] for i in ok])
                                           for x in (felt, req, depth, press, stamp))
    ratio = felt_a / req_a
    within = float(np.mean(np.abs(ratio - 1.0) <= WEBER_FRACTION))
    gate = "object_depth" if scene is not None else "sheet_depth"
    return {"n": len(ok), "basis": basis, "gate": gate,
            "ratio": {"median": float(np.median(ratio)), "p5": float(np.percentile(ratio, 5)),
                      "p95": float(np.percentile(ratio, 95))},
            "within_15pct": within, "per_press": _per_press(press_a, ratio),
            "felt_n": float(np.median(felt_a)), "requested_n": float(np.median(req_a)),
            "felt_stiffness_n_per_m": float(np.median(felt_a / dep_a)),
            "samples": {"depth_m": dep_a.tolist(), "felt_n": felt_a.tolist(), "requested_n": req_a.tolist(),
                        "stamp_s": st_a.tolist()},
            "target": f">= {WITHIN_TARGET:.2f} of pressed samples (>= {MIN_DEPTH * 1e3:g} mm into the "
                      f"{'object' if scene is not None else 'sheet'}) with the true force within "
                      f"± {100 * WEBER_FRACTION:.0f} % of the mapped request at the surface contact (Weber "
                      "fraction, Bergmann Tiest & Kappers 2009)",
            "verdict": "met" if within >= WITHIN_TARGET else "MISSED"}


#: the urethane sheet's working strain (Treloar 1975 neo-Hookean range, docs/planner.md)
STRAIN_LIMIT = 0.30
#: the true clamp strain may exceed the planned one by at most this
STRAIN_OVER_PLAN = 0.02


def sheet_summary(d: dict[str, list]) -> dict:
    """The true sheet against the plan, from a bag: ``strain_true_max`` (``/world/sheet`` stretch),
    ``strain_over_plan_max`` (true minus the newest ``/sheet/target`` stretch planned before it), and
    ``one_arm_holds``: joint-state cycles of one bridge holding (``bridge_status`` "hold…"; not
    "hold:no_target", a bridge before its first target) while the other's newest state does not; with
    ``targets`` and ``verdict`` (strain ≤ :data:`STRAIN_LIMIT`, ≤ :data:`STRAIN_OVER_PLAN` over the plan, no
    one-arm hold). ``{}`` without ``/world/sheet``."""
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
    states = sorted(
        [(m.header.stamp, m.arm, m.bridge_status.startswith("hold") and m.bridge_status != "hold:no_target")
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
            "targets": {"strain_true_max": STRAIN_LIMIT, "strain_over_plan_max": STRAIN_OVER_PLAN,
                        "one_arm_holds": 0},
            "verdict": "met" if met else "MISSED"}


def inclusion_contrast(d: dict[str, list], scene, scales=None) -> dict:
    """The inclusion's contrast a finger felt, from true forces at matched depth: judged ``/world/contact``
    samples (:func:`_pressed`: ≥ :data:`MIN_DEPTH` into the object when ``scene`` has an object, else into the
    sheet) over the inclusion's footprint (the contact on the surface, :func:`surface_points`, within the
    inclusion's radius of the table's point nearest its centre) against those around it (beyond 2 radii), in 1
    mm bins of the true sheet depth holding both; per bin the median force over, over the median around, less
    1; the median over bins. The requested contrast is the object's own (its force–depth table at the same
    samples and surface contacts, unmapped), the presented request's the mapped one (``stiffness_scale`` and
    the planner's ``contrast_gain`` in force, from its heartbeats). ``{}`` without a scene inclusion, the
    table, or a bin with both. Returns ``{"felt", "requested", "mapped", "contrast_gain"`` (the gains in
    force, sorted), ``"bins"``, ``"n_over", "n_around"}`` (contrasts as fractions: 0.25 = 25 % stiffer over
    the inclusion)."""
    table = force_depth_table(d)
    incs = list(getattr(scene, "inclusions", []) or []) if scene is not None else []
    if table is None or not incs:
        return {}
    inc = incs[0]
    c, r = np.asarray(inc.center, float), float(inc.radius)
    top = table.points[int(np.argmin(np.linalg.norm(table.points - c, axis=1)))]
    pressed = _pressed(d, scene if getattr(scene, "object", None) is not None else None, table)
    if not pressed:
        return {}
    scales = planner_scales(d) if scales is None else scales
    arrival = np.array([x["t"] for x in pressed])
    sc = np.nan_to_num(scales_at(scales, arrival), nan=1.0)
    gains = np.nan_to_num(scales_at(planner_gains(d), arrival), nan=1.0)
    rows = []
    for x, s, g in zip(pressed, sc, gains, strict=True):
        m, q = x["m"], x["q"]
        dist = float(np.linalg.norm(q - top))
        where = "over" if dist <= r else ("around" if dist >= 2 * r else None)
        if where is None:
            continue
        rows.append((where, m.depth, m.force, table.force_at(q, m.depth),
                     table.mapped(q, m.depth, float(s), float(g))[0]))
    bins = []
    for b in np.arange(MIN_DEPTH, max((x[1] for x in rows), default=0.0) + 1e-3, 1e-3):
        over = [x for x in rows if x[0] == "over" and b <= x[1] < b + 1e-3]
        around = [x for x in rows if x[0] == "around" and b <= x[1] < b + 1e-3]
        if len(over) >= 3 and len(around) >= 3:
            med = lambda xs, k: float(np.median([x[k] for x in xs]))     # noqa: E731
            bins.append({"depth_mm": 1e3 * (b + 5e-4), "felt": med(over, 2) / med(around, 2) - 1.0,
                         "requested": med(over, 3) / med(around, 3) - 1.0,
                         "mapped": med(over, 4) / med(around, 4) - 1.0,
                         "n_over": len(over), "n_around": len(around)})
    if not bins:
        return {}
    return {"felt": float(np.median([b["felt"] for b in bins])),
            "requested": float(np.median([b["requested"] for b in bins])),
            "mapped": float(np.median([b["mapped"] for b in bins])),
            "contrast_gain": sorted({float(g) for g in gains}), "bins": bins,
            "n_over": sum(b["n_over"] for b in bins), "n_around": sum(b["n_around"] for b in bins)}


#: the tension must follow the finger within this (ms)
FOLLOW_TARGET_MS = 60.0


def follow_lag(d: dict[str, list], window: float = 0.5) -> dict:
    """How late the true sheet's tension follows the finger: the delay τ (ms, 0–200 in 1 ms steps) at which
    the rate of the true clamp strain (``/world/sheet`` stretch) best correlates with the rate of the planned
    one as a function of the fingertip's exposure (``/sheet/target`` stretch at its ``source_stamp``, delayed
    by τ); both resampled at 2 ms, over the ``window`` s around every sample pressed :data:`MIN_DEPTH` into
    the sheet (:func:`_pressed` without a scene). Rates, not
    values: the identified sheet's strain differs from the truth's by a near-constant offset, which made the
    fit on values flat. A stroke asks a ramp, not a step, so the delay is the figure: 90 % of a step is
    reached a rise time later. ``{}`` without samples. Returns
    ``{"follow_ms", "correlation", "n", "target_ms", "verdict"}``."""
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
    for c in (x["m"].header.stamp for x in pressed):
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


def judged_contacts(d: dict[str, list], scene=None) -> np.ndarray:
    """(n, 2) m: where on the sheet each judged sample (:func:`_pressed`) was planned, (u along the clamp
    line, v across) from the sheet's centre, read from the newest ``/sheet/target`` at or before it (its
    contact point less its origin, on its axes); (0, 2) without either topic."""
    pressed, targets = _pressed(d, scene, force_depth_table(d)), d.get("/sheet/target", [])
    if not pressed or not targets:
        return np.zeros((0, 2))
    tt = np.array([t for t, _ in targets])
    out = []
    for r in pressed:
        k = int(np.searchsorted(tt, r["t"], side="right")) - 1
        if k < 0:
            continue
        m = targets[k][1]
        dv = np.asarray(m.contact_point, float) - np.asarray(m.sheet_origin, float)
        out.append((float(dv @ np.asarray(m.axis_u, float)), float(dv @ np.asarray(m.axis_v, float))))
    return np.array(out, float).reshape(-1, 2)

