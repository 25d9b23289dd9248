"""Table I of a recorded run, from its bag only (the numbers of :mod:`flexsheet.analysis.report`).

Per stroking segment, keyed by moving time in seconds (``"10"``; ``"stroke_push_4"`` for a stroke with a
push), the ``/world/finger`` truth at each fingertip's exposure naming the segment:

* ``felt`` (the headline): the true fingertip against the true sheet (``/world/sheet``);
* ``paper``: the paper's own method, the measured fingertip against the sheet the display believes (its
  kinematics on the joint readback);
* the top-level rows (``summary["10"]``): the measured fingertip against the true sheet, the metric of
  ``flexsheet experiment stroke`` (:func:`flexsheet.analysis.table1.scene_table1_row`).

A segment whose moving phase the bag does not see end (the run stopped inside it) is *partial*
(:func:`stroke_segments`) and gets no verdict (:mod:`flexsheet.analysis.report_verdicts`).
"""

from __future__ import annotations

from collections import defaultdict
from pathlib import Path

import numpy as np

from flexsheet.analysis.report_head import head_summary
from flexsheet.analysis.report_motion import motion_summary
from flexsheet.analysis.report_placement import placement
from flexsheet.analysis.report_softness import (
    WEBER_FRACTION,
    felt_force,
    follow_lag,
    inclusion_contrast,
    judged_contacts,
    sheet_summary,
)
from flexsheet.analysis.report_timing import compliance_summary, latency_hops, watchdog_faults
from flexsheet.analysis.report_verdicts import judge, table1_verdicts
from flexsheet.analysis.table1 import (
    FELT_TARGET_FACTOR,
    PAPER_TABLE1,
    STROKE_MODES,
    TARGET_FACTOR,
    errors_row,
    scene_table1_row,
    segment_key,
    table1,
    target,
)
from flexsheet.model.scenes import Scene, paper_scene
from flexsheet.model.sheet import frame_from_clamps
from flexsheet.planning.shape import planner_shape
from flexsheet.runtime.bag_read import read_bag
from flexsheet.runtime.codec import DecodeError, decode_any

__all__ = ["analyse", "table1_rows", "felt_and_paper", "sheet_delay", "stroke_segments",
           "is_paper", "TREMOR_WINDOW", "DELAY_LAGS"]

#: the finger's slow motion is its 0.21 s moving average
#: (21 samples at the world's 100 Hz): the rest is tremor
TREMOR_WINDOW = 21
#: lags tried by :func:`sheet_delay`, s
DELAY_LAGS = np.arange(-0.030, 0.150001, 0.001)


def _load(bags: list[Path]) -> dict[str, list]:
    out: dict[str, list] = defaultdict(list)
    for m in (m for bag in bags for m in read_bag(bag)):
        try:
            out[m.topic].append((m.log_time, decode_any(m.frames)))
        except DecodeError:
            out["<rejected>"].append((m.log_time, None))
    return out


def _interp_sheet(sheets: list, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    ts = np.array([s.header.stamp for _, s in sheets])
    org = np.array([s.origin for _, s in sheets])
    nrm = np.array([s.normal for _, s in sheets])
    o = np.stack([np.interp(t, ts, org[:, k]) for k in range(3)], axis=1)
    n = np.stack([np.interp(t, ts, nrm[:, k]) for k in range(3)], axis=1)
    return o, n / np.linalg.norm(n, axis=1, keepdims=True)


def analyse(bags: Path | list[Path], heartbeats: list | None = None, scene: Scene | None = None,
            series: dict | None = None) -> dict:
    """The summary of a bag, or of the parts of one run (a respawned recorder continues in
    ``<stem>.1.mcap``…), on ``scene`` (``None``: the paper's cylinder): ``bags``, ``counts`` per topic,
    ``run`` and ``segments`` (:func:`stroke_segments`), the rows of :func:`table1_rows`, ``compliance`` (its
    ``felt``, ``follow``, ``inclusion_contrast``: :mod:`flexsheet.analysis.report_softness`), ``placement``
    (:func:`~flexsheet.analysis.report_placement.placement`), ``latency_ms``, ``faults`` and the verdicts
    (:func:`flexsheet.analysis.report_verdicts.judge`: ``headline``). The recorded ``/diagnostics`` (arrival
    time, Heartbeat) pairs are appended to ``heartbeats`` if given, the per-sample Table I series to
    ``series`` (:func:`felt_and_paper`)."""
    bags = [bags] if isinstance(bags, Path) else list(bags)
    d = _load(bags)
    for msgs in d.values():
        msgs.sort(key=lambda tm: tm[0])
    if heartbeats is not None:
        heartbeats.extend(d.get("/diagnostics", []))
    summary: dict = {"bags": [str(b) for b in bags], "counts": {k: len(v) for k, v in d.items()}}
    segments, run = stroke_segments(d.get("/world/finger", []), d.get("/fingertip", []))
    summary["run"], summary["segments"] = run, segments
    summary.update(table1_rows(d, scene, series, segments))
    summary["compliance"] = compliance_summary(d)
    if summary["compliance"]:
        felt = felt_force(d, scene=scene or paper_scene())
        samples = felt.pop("samples", None)
        if samples:
            ratio = np.array(samples["felt_n"]) / np.array(samples["requested_n"])
            felt["by_status"] = force_by_status(plan_statuses(d), np.array(samples["stamp_s"]), ratio)
        if series is not None and samples:
            series["compliance"] = samples
        summary["compliance"]["felt"] = felt
        uv = np.round(judged_contacts(d, scene or paper_scene()) * 500.0) / 500.0    # to 2 mm
        if len(uv):
            pos, n = np.unique(uv, axis=0, return_counts=True)
            summary["compliance"]["contacts_on_sheet"] = {
                "uv_m": pos.tolist(), "n": n.tolist(),
                "note": "where on the sheet the judged samples were planned (u along the clamp line, v "
                        "across), to 2 mm"}
        fl = follow_lag(d)
        if fl:
            summary["compliance"]["follow_ms"] = fl["follow_ms"]
            summary["compliance"]["follow"] = fl
        ic = inclusion_contrast(d, scene)
        if ic:
            summary["compliance"]["inclusion_contrast_felt"] = ic["felt"]
            summary["compliance"]["inclusion_contrast_requested"] = ic["requested"]
            summary["compliance"]["inclusion_contrast"] = ic
        summary["compliance"]["saturated"] = summary["compliance"]["all"]["at_limit"]
    pl = placement(d, scene or paper_scene())
    if pl:
        summary["placement"] = pl
    summary["sheet"] = {**sheet_summary(d), **motion_summary(d)}
    head = head_summary(d, scene or paper_scene(), series)
    if head:
        summary.update(head)
    summary["latency_ms"] = latency_hops(d)
    summary["faults"] = watchdog_faults(d)
    if summary.get("delay"):
        summary["delay"]["chain_exposure_to_sheet_at_pose_ms"] = \
            summary["latency_ms"]["chain"]["exposure_to_sheet_at_pose"]["median"]
    judge(summary)
    return summary


def stroke_segments(truths: list, tips: list | None = None) -> tuple[dict, dict]:
    """The moving phases of the Table I strokes in the truth (time-sorted (arrival, FingerTruth) pairs;
    samples of a paused script are skipped: a pass resumes after them).

    Returns ``segments``: key → ``{"mode", "moving_time_s", "passes", "moved_s", "coverage", "partial",
    "expected_n"}`` (``partial``: a pass whose moving phase the bag does not see end; ``coverage``: moved s
    over moving time × passes; ``expected_n``: fingertips a full segment gets at the fingertips' median rate)
    and ``run``: ``{"partial", "note"}`` (partial when the bag ends before a segment's trailing hold)."""
    passes: list[dict] = []
    cur, prev = None, None
    approach: dict[int, float] = {}
    for _, m in truths:
        t = float(m.header.stamp)
        if m.phase == "paused":
            prev = None
            continue
        if m.phase == "approach":
            approach[m.segment] = t
        if m.phase != m.mode:
            if cur is not None:
                cur["ended"], cur = True, None
            continue
        if cur is None or cur["segment"] != m.segment:
            if cur is not None:
                cur["ended"] = True
            cur = {"key": segment_key(m), "segment": m.segment, "mode": m.mode,
                   "moving_time_s": m.moving_time,
                   "t0": t, "moved_s": 0.0, "ended": False}
            passes.append(cur)
        elif prev is not None:
            cur["moved_s"] += t - prev
        prev = t
    rate = _tip_rate(tips or [])
    segments: dict = {}
    for p in (p for p in passes if p["mode"] in STROKE_MODES):
        s = segments.setdefault(p["key"],
                                {"mode": p["mode"], "moving_time_s": p["moving_time_s"], "passes": 0,
                                 "moved_s": 0.0, "partial": False})
        s["passes"] += 1
        s["moved_s"] += p["moved_s"]
        s["partial"] = s["partial"] or not p["ended"]
    for s in segments.values():
        full = s["moving_time_s"] * s["passes"]
        s["coverage"] = min(1.0, s["moved_s"] / full) if full > 0 else None
        s["expected_n"] = int(round(full * rate)) if rate else None
    return segments, _run_state([tm for tm in truths if tm[1].phase != "paused"], passes, approach)


def _tip_rate(tips: list) -> float | None:
    """Fingertips per s (valid or not): one over the median interval of their exposure stamps."""
    t = np.sort([m.exposure_stamp for _, m in tips])
    dt = np.diff(t)
    dt = dt[dt > 0]
    return float(1.0 / np.median(dt)) if dt.size else None


def _run_state(truths: list, passes: list[dict], approach: dict[int, float]) -> dict:
    if not truths:
        return {"partial": False, "note": "no /world/finger truth in the bag: completeness unknown"}
    last = truths[-1][1]
    if passes and not passes[-1]["ended"]:
        p = passes[-1]
        frac = p["moved_s"] / p["moving_time_s"] if p["moving_time_s"] > 0 else 0.0
        return {"partial": True, "note": f"the bag ends inside segment {p['key']} s ({p['mode']}, "
                                         f"{100 * frac:.0f} % of its {p['moving_time_s']:g} s moving time)"}
    moved = any(p["segment"] == last.segment and p["t0"] > approach.get(last.segment, -np.inf)
                for p in passes)
    if last.phase != "idle" or not moved:
        return {"partial": True, "note": f"the bag ends before the {last.mode} {last.moving_time:g} s "
                                         "segment moved"}
    return {"partial": False, "note": "the bag ends in a segment's closing hold, after its stroke"}


def _stroke_groups(tips: list, truths: list) -> tuple[dict[str, list], int]:
    """Valid fingertips grouped by the stroking segment the truth was playing at their exposure (keys of
    :func:`segment_key`), and the number of invalid ones."""
    tt = np.array([m.header.stamp for _, m in truths])
    groups: dict[str, list] = defaultdict(list)
    n_invalid = 0
    for _, m in tips:
        if not m.valid:
            n_invalid += 1
            continue
        k = int(np.searchsorted(tt, m.exposure_stamp, side="right")) - 1
        if k < 0:
            continue
        truth = truths[k][1]
        if truth.phase == truth.mode and truth.mode in STROKE_MODES:
            groups[segment_key(truth)].append(m)
    return groups, n_invalid


def is_paper(sc: Scene) -> bool:
    """True when ``sc``'s object is the paper's cylinder (same size and pose)."""
    o, p = sc.object, paper_scene().object
    return o.kind == "cylinder" and bool(np.allclose([o.radius, o.length, *o.pose.position, *o.pose.rpy_deg],
                                                     [p.radius, p.length, *p.pose.position, *p.pose.rpy_deg],
                                                     rtol=0.0, atol=1e-9))


def table1_rows(d: dict[str, list], scene: Scene | None = None, series: dict | None = None,
                segments: dict | None = None) -> dict:
    """Per stroking segment with ≥ 10 fingertips inside the recorded sheet states: the measured fingertip's
    row (:func:`flexsheet.analysis.table1.scene_table1_row` on ``scene``, default the paper's cylinder;
    ``paper``: the paper's published row, on the paper's cylinder only), plus ``fingertip_invalid``,
    ``table1`` (:func:`felt_and_paper`) and ``delay`` (:func:`sheet_delay`); empty without ``/fingertip``,
    ``/world/finger`` and ``/world/sheet``. ``d``: topic → time-sorted (arrival s, message) pairs."""
    tips, truths, sheets = d.get("/fingertip", []), d.get("/world/finger", []), d.get("/world/sheet", [])
    if not (truths and sheets and tips):
        return {}
    groups, n_invalid = _stroke_groups(tips, truths)
    scene = scene if scene is not None else paper_scene()
    paper = is_paper(scene)
    s_ts = np.array([s.header.stamp for _, s in sheets])
    out: dict = {}
    for key, ms in groups.items():
        ms = [m for m in ms if s_ts[0] <= m.exposure_stamp <= s_ts[-1]]
        if len(ms) < 10:
            continue
        origin, normal = _interp_sheet(sheets, np.array([m.exposure_stamp for m in ms]))
        row = scene_table1_row(scene, np.array([m.position for m in ms]), origin, normal)
        if key in PAPER_TABLE1 and paper:
            row["paper"] = PAPER_TABLE1[key]
        out[key] = row
    out["fingertip_invalid"] = n_invalid
    out["table1"] = felt_and_paper(d, groups, scene, s_ts, series, segments, paper)
    out["delay"] = sheet_delay(d, groups, scene)
    return out


def _interp_points(samples: list, t: np.ndarray, attr: str = "position") -> np.ndarray:
    ts = np.array([m.header.stamp for _, m in samples])
    v = np.array([getattr(m, attr) for _, m in samples], float)
    return np.stack([np.interp(t, ts, v[:, k]) for k in range(v.shape[1])], axis=1)


def _believed_sheet(d: dict[str, list], t: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """The sheet the display believes at times ``t``: its kinematics on the joint readback (the bridges'
    ``ArmJointState.pose``), both clamps interpolated, :func:`flexsheet.model.sheet.frame_from_clamps`."""
    left, right = d.get("/arm/left/joint_state", []), d.get("/arm/right/joint_state", [])
    if len(left) < 2 or len(right) < 2:
        return None
    poses = []
    for arm in (left, right):
        ts = np.array([m.header.stamp for _, m in arm])
        idx = np.clip(np.searchsorted(ts, t), 0, len(ts) - 1)   # the readback at or just after each instant
        poses.append([arm[i][1].pose for i in idx])
    o, n = np.empty((len(t), 3)), np.empty((len(t), 3))
    for i, (tl, tr) in enumerate(zip(*poses, strict=True)):
        o[i], n[i], _, _ = frame_from_clamps(tl, tr)
    return o, n


def felt_and_paper(d: dict[str, list], groups: dict[str, list], scene: Scene, s_ts: np.ndarray,
                   series: dict | None = None, segments: dict | None = None,
                   paper_scene_: bool = True) -> dict:
    """Table I two ways per stroking segment: ``felt`` (the true fingertip, interpolated at each exposure,
    against the true sheet: the row of :func:`flexsheet.analysis.table1.errors_row` plus ``angle3d_mean_deg``,
    the full 3-D angle between the object's normal and the sheet's) and ``paper`` (the measured fingertip
    against the sheet the display believes). Plus ``decomposition`` (:func:`_decomposition`), ``by_status``
    (:func:`felt_by_status`), ``targets`` (Δθ
    mean, deg: the paper's ÷ :data:`~flexsheet.analysis.table1.FELT_TARGET_FACTOR` felt, ÷
    :data:`~flexsheet.analysis.table1.TARGET_FACTOR` paper), ``target_source`` and ``verdicts``
    (:func:`flexsheet.analysis.report_verdicts.table1_verdicts`: on the paper's cylinder only, none for a
    partial segment). ``series`` receives per segment the exposure times (s from the first) and per-sample Δθ
    (deg) of both."""
    truths, sheets = d.get("/world/finger", []), d.get("/world/sheet", [])
    shape = planner_shape(scene)
    statuses = plan_statuses(d)
    out: dict = {"felt": {}, "paper": {}}
    for key, ms in groups.items():
        ms = [m for m in ms if s_ts[0] <= m.exposure_stamp <= s_ts[-1]]
        if len(ms) < 10:
            continue
        t = np.array([m.exposure_stamp for m in ms])
        true_tip = _interp_points(truths, t)
        origin, normal = _interp_sheet(sheets, t)
        felt = table1(shape, true_tip, origin, normal, scene)
        row = errors_row(shape, felt)
        n_true = _normals(shape, true_tip)
        row["angle3d_mean_deg"] = float(_angles_deg(n_true, normal).mean())
        out["felt"][key] = row
        believed = _believed_sheet(d, t)
        paper = None
        if believed is not None:
            paper = table1(shape, np.array([m.position for m in ms]), *believed, scene)
            out["paper"][key] = errors_row(shape, paper)
        if series is not None:
            series[key] = {"t_s": (t - t[0]).tolist(), "felt_deg": np.degrees(felt.dtheta).tolist()}
            if paper is not None:
                series[key]["paper_deg"] = np.degrees(paper.dtheta).tolist()
        out.setdefault("decomposition", {})[key] = _decomposition(d, ms, shape, n_true, normal, believed)
        out.setdefault("by_status", {})[key] = felt_by_status(statuses, t, np.degrees(felt.dtheta))
    out["targets"] = {kind: {k: target(k, f)["dtheta_mean_deg"] for k in PAPER_TABLE1}
                      for kind, f in (("felt", FELT_TARGET_FACTOR), ("paper", TARGET_FACTOR))}
    out["target_source"] = {kind: f"paper Table I ÷ {f:g}"
                            for kind, f in (("felt", FELT_TARGET_FACTOR), ("paper", TARGET_FACTOR))}
    out["verdicts"] = table1_verdicts(out, segments or {}, paper_scene_)
    return out


#: the plan's status classes of :func:`felt_by_status`, first match wins: the sheet held where the arms
#: cannot reach, held off the head, turned only part of the way, held for another reason, rate-limited,
#: else ok
STATUS_CLASSES = (("unreachable", "unreachable"), ("keep_out", "keep_out"), ("reach:nearest", "nearest"),
                  ("hold:", "hold"), ("rate_limited", "rate_limited"))


def status_class(status: str) -> str:
    """The class (:data:`STATUS_CLASSES`, else ``"ok"``) of a plan's ``status`` ("ok", "rate_limited;
    ik:left:limit:J3;unreachable", ...)."""
    for key, name in STATUS_CLASSES:
        if key in status:
            return name
    return "ok"


def plan_statuses(d: dict[str, list]) -> dict[float, str]:
    """{source_stamp: status} of the bag's ``/sheet/target`` messages (``d``: topic → [(t, message)])."""
    return {m.source_stamp: m.status for _, m in d.get("/sheet/target", [])}


def felt_by_status(by_src: dict[float, str], t: np.ndarray, dtheta_deg: np.ndarray) -> dict:
    """The felt error split by what the planner said of the plan made from each fingertip (``by_src``:
    :func:`plan_statuses`, the plan with that ``source_stamp``; class :func:`status_class`, ``"no plan"``
    without one): per class ``share`` of the samples, ``mean_deg`` of their Δθ and ``of_mean`` (their share
    of the mean: the classes' ``of_mean`` add up to 1, so the mean splits additively). ``t`` (N,): the
    fingertips' exposure stamps, s; ``dtheta_deg`` (N,): each sample's felt Δθ, deg."""
    cls = np.array([status_class(by_src[x]) if x in by_src else "no plan" for x in t.tolist()])
    total = float(dtheta_deg.sum())
    out = {}
    for c in sorted(set(cls.tolist())):
        m = cls == c
        out[c] = {"share": float(m.mean()), "mean_deg": float(dtheta_deg[m].mean()),
                  "of_mean": float(dtheta_deg[m].sum() / total) if total > 0.0 else 0.0}
    return out


def force_by_status(by_src: dict[float, str], t: np.ndarray, ratio: np.ndarray) -> dict:
    """The force presses split by what the planner said of the plan in force at each judged sample (the
    newest plan whose ``source_stamp`` is at or before its stamp; ``by_src``: :func:`plan_statuses`; class
    :func:`status_class`, ``"no plan"`` before the first): per class ``share`` of the samples,
    ``within_15pct`` among them and ``of_misses`` (their share of all samples outside 15 %: the classes'
    ``of_misses`` add up to 1). ``t`` (N,) s: the samples' stamps; ``ratio`` (N,): felt / requested force."""
    src = np.array(sorted(by_src))
    k = np.searchsorted(src, t, side="right") - 1
    cls = np.array([status_class(by_src[src[i]]) if i >= 0 else "no plan" for i in k.tolist()])
    miss = np.abs(ratio - 1.0) > WEBER_FRACTION
    n_miss = int(miss.sum())
    out = {}
    for c in sorted(set(cls.tolist())):
        m = cls == c
        out[c] = {"share": float(m.mean()), "within_15pct": float(1.0 - miss[m].mean()),
                  "of_misses": float(miss[m].sum() / n_miss) if n_miss else 0.0}
    return out


def _normals(shape, points: np.ndarray) -> np.ndarray:
    """The object's unit normals (N, 3) at the points of ``shape`` nearest ``points`` (N, 3) m."""
    if not shape.convex and hasattr(shape, "closest_many") and len(points):   # a mesh: one batched query
        return shape.closest_many(points)[1]
    return np.array([shape.project(tuple(p)).normal for p in points])


def _angles_deg(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Angles (N,) deg between the unit directions (N, 3) ``a`` and ``b`` (sign-blind, as normals of a
    plane)."""
    return np.degrees(np.arccos(np.clip(np.abs(np.sum(a * b, axis=1)), 0.0, 1.0)))


def _decomposition(d: dict[str, list], ms: list, shape, n_true: np.ndarray, sheet_normal: np.ndarray,
                   believed) -> dict:
    """What the felt error is made of, each as a mean angle (deg) between object normals or sheet normals:
    ``tremor`` (the true finger against its own slow motion, :data:`TREMOR_WINDOW`), ``camera`` (the measured
    fingertip against the true one), ``prediction`` (the predicted fingertip against the true one at the
    horizon), ``kinematics`` (the sheet the display believes against the true sheet) and ``slow_finger``
    (the felt error against the finger's slow motion: what is left without the tremor). ``n_true``: the
    object's normals (N, 3) at the true fingertip of each of ``ms``."""
    truths = d["/world/finger"]
    ts = np.array([m.header.stamp for _, m in truths])
    pos = np.array([m.position for _, m in truths], float)
    ker = np.ones(TREMOR_WINDOW) / TREMOR_WINDOW
    slow = np.stack([np.convolve(pos[:, k], ker, mode="same") for k in range(3)], axis=1)
    t = np.array([m.exposure_stamp for m in ms])
    n_slow = _normals(shape, np.stack([np.interp(t, ts, slow[:, k]) for k in range(3)], axis=1))
    h = float(ms[0].prediction_horizon)

    def angle(a: np.ndarray, b: np.ndarray) -> float:
        return float(_angles_deg(a, b).mean())

    out = {"tremor": angle(n_true, n_slow),
           "camera": angle(n_true, _normals(shape, np.array([m.position for m in ms]))),
           "prediction": angle(_normals(shape, _interp_points(truths, t + h)),
                               _normals(shape, np.array([m.predicted_position for m in ms]))),
           "slow_finger": angle(n_slow, sheet_normal)}
    if believed is not None:
        out["kinematics"] = angle(believed[1], sheet_normal)
    return out


def sheet_delay(d: dict[str, list], groups: dict[str, list], scene: Scene) -> dict:
    """The prediction check: the lag L (s) that best aligns the true sheet's normal at t with the object's
    normal at the true fingertip at t − L (least mean angle over :data:`DELAY_LAGS`, on the 10 s stroke, else
    the longest segment). The prediction already leads by its horizon h, so h + L is the horizon that would
    cancel the lag. Returns ``{"segment", "horizon_ms", "residual_lag_ms", "exposure_to_sheet_ms" (h + L),
    "angle_at_best_deg", "stroke_speed_mm_per_s"}`` (the true finger's median speed in that segment), or
    {}."""
    truths, sheets = d.get("/world/finger", []), d.get("/world/sheet", [])
    if not groups or len(truths) < 10 or len(sheets) < 10:
        return {}
    key = "10" if len(groups.get("10", ())) >= 10 else max(groups, key=lambda k: len(groups[k]))
    t = np.array([m.exposure_stamp for m in groups[key]])
    s_ts = np.array([m.header.stamp for _, m in sheets])
    t = t[(t >= s_ts[0]) & (t <= s_ts[-1])]
    if len(t) < 10:
        return {}
    shape = planner_shape(scene)
    f_ts = np.array([m.header.stamp for _, m in truths])
    sel = (f_ts >= t[0] - DELAY_LAGS[-1] - 0.05) & (f_ts <= t[-1] - DELAY_LAGS[0] + 0.05)
    fn = _normals(shape, np.array([m.position for (_, m), ok in zip(truths, sel, strict=True) if ok]))
    fts = f_ts[sel]
    _, n_s = _interp_sheet(sheets, t)
    best = (np.inf, 0.0)
    for lag in DELAY_LAGS:
        nf = np.stack([np.interp(t - lag, fts, fn[:, k]) for k in range(3)], axis=1)
        nf /= np.linalg.norm(nf, axis=1, keepdims=True)
        a = float(_angles_deg(nf, n_s).mean())
        best = min(best, (a, float(lag)))
    h = float(groups[key][0].prediction_horizon)
    moving = [np.linalg.norm(m.velocity) for _, m in truths
              if m.phase == m.mode and segment_key(m) == key and t[0] <= m.header.stamp <= t[-1]]
    return {"segment": key, "horizon_ms": h * 1e3, "residual_lag_ms": best[1] * 1e3,
            "exposure_to_sheet_ms": (h + best[1]) * 1e3, "angle_at_best_deg": best[0],
            "stroke_speed_mm_per_s": float(np.median(moving) * 1e3) if moving else None}
