"""Report of a full-graph run, computed from the recorded bag only (``launch/sim.yaml``'s ``report``).

Reads ``OUT/*.mcap`` (the recorder's bag) and writes ``OUT/summary.json``, ``OUT/report.md`` and charts
(``OUT/table1.png``, ``OUT/latency.png`` with JSON beside them), and prints Table I and the latency budget.

Table I (paper §V-C, Fig. 9) per stroking segment, keyed by moving time in seconds like
``flexsheet experiment stroke``: D = the measured fingertip (``/fingertip``, valid samples, while the
target mark moves: the ``/world/finger`` truth at the exposure time names the segment's ``mode``,
``moving_time`` and ``phase``), the actual sheet = ``/world/sheet`` (FK of the arms' measured joints)
interpolated at the fingertip's exposure time, the row by :func:`flexsheet.experiments.table1.table1_row`
(the same metric as the in-process experiment, in the cross-section of Fig. 9) with the paper's numbers
from :data:`flexsheet.experiments.table1.PAPER_TABLE1`.

Latency, one chain per fingertip sample, from the stamps the nodes set (never the recorder's receive
times), so the hops add up to the chain (``latency_ms.chain``; every value median, p99 and n, ms):

* arm chain: ``exposure_to_camera_frame`` (the frame's ``header.stamp`` − mid-exposure: readout and
  transfer), ``camera_frame_to_fingertip`` (the fingertip's ``sent_stamp`` − the frame's stamp),
  ``fingertip_to_sheet_target``, ``sheet_target_to_arm_command`` (the first command carrying the sample,
  ``write_stamp``, the earliest of either arm), ``arm_command_to_sheet_at_pose`` (the first readback whose FK
  clamp pose is within :data:`POSE_TOL_M` and :data:`POSE_TOL_RAD` of that sample's arm target, the later
  of the two arms; a sample neither arm reached before the next target took over is not counted:
  ``sheet_at_pose_reached`` gives the share); ends: ``exposure_to_arm_command``,
  ``exposure_to_sheet_at_pose``;
* render chain: ``fingertip_to_deformation``, ``deformation_to_rendered_frame``, ``rendered_to_projected``
  (the first projector vsync after the frame plus the projector's input latency,
  :meth:`flexsheet.twin.timing.LabTiming.projected_at`); end: ``exposure_to_projected``.

All hosts of the sim run share one clock; across PCs see docs/deploy.md on time sync.

The twin the run used (``twin.realism``, ``twin.truth_seed``: the launch file's top-level ``twin:`` section,
else the world node's ``twin`` param, else the world's defaults) is recorded in ``summary.json`` beside the
Table I rows (``10.dtheta_mean_deg`` …, each row with Δd in both conventions, :data:`DD_CONVENTION`).

The scene (issue 17; ``scene``: ``name``, ``file``, ``kind``, ``description``, ``source``: the launch file's
top-level ``scene:``, else the world node's ``scene`` param, else the paper's cylinder) is the object of the
metric: D is projected onto *its* surface and Δθ is measured in the normal section along *its* stroke
(:func:`flexsheet.experiments.table1.scene_table1_row`; for the cylinder exactly the paper's Fig. 9 cross
section). The paper's row is attached to a row only on the paper's cylinder. ``compliance`` summarises the
tension the planner set at every contact (``/sheet/target``: tension N/m, presented and requested stiffness
N/m, the share of targets whose stretch is at a limit) per stroking segment and over the whole run.
"""

from __future__ import annotations

import json
import os
import sys
from collections import defaultdict
from pathlib import Path

import numpy as np

from flexsheet.experiments.table1 import (
    DD_CONVENTION,
    FELT_TARGET_FACTOR,
    PAPER_TABLE1,
    TARGET_FACTOR,
    errors_row,
    scene_table1_row,
    table1,
    target,
)
from flexsheet.model.scenes import Scene, load_scene, paper_scene
from flexsheet.runtime.bag import read_bag
from flexsheet.runtime.codec import DecodeError, decode_any

__all__ = ["analyse", "table1_rows", "latency_hops", "twin_settings", "scene_settings", "compliance_summary",
           "main"]

#: the truth's modes whose moving phase is a Table I stroke
STROKE_MODES = ("stroke", "stroke_push")


def _load(bags: list[Path]) -> dict[str, list]:
    out: dict[str, list] = defaultdict(list)
    for m in (m for bag in bags for m in read_bag(bag)):
        try:
            out[m.topic].append((m.log_time, decode_any(m.frames)))
        except DecodeError:
            out["<rejected>"].append((m.log_time, None))
    return out


def _stats(x) -> dict:
    x = np.asarray(x, dtype=float) * 1e3
    if x.size == 0:
        return {"median": None, "p99": None, "n": 0}
    return {"median": float(np.median(x)), "p99": float(np.percentile(x, 99)), "n": int(x.size)}


def _interp_sheet(sheets: list, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    ts = np.array([s.header.stamp for _, s in sheets])
    org = np.array([s.origin for _, s in sheets])
    nrm = np.array([s.normal for _, s in sheets])
    o = np.stack([np.interp(t, ts, org[:, k]) for k in range(3)], axis=1)
    n = np.stack([np.interp(t, ts, nrm[:, k]) for k in range(3)], axis=1)
    return o, n / np.linalg.norm(n, axis=1, keepdims=True)


def analyse(bags: Path | list[Path], heartbeats: list | None = None, scene: Scene | None = None,
            series: dict | None = None) -> dict:
    """Table I per segment and the latency per hop from a bag, or the parts of one run (a respawned recorder
    continues in ``<stem>.1.mcap``…), on ``scene`` (``None``: the paper's cylinder). Returns the summary dict
    (``bags``, ``counts`` per topic, the Table I rows of :func:`table1_rows`, ``latency_ms`` of
    :func:`latency_hops`, ``compliance`` of :func:`compliance_summary`); the recorded ``/diagnostics``
    (arrival time, Heartbeat) pairs are appended to ``heartbeats`` if given, the per-sample Table I series to
    ``series`` (:func:`felt_and_paper`)."""
    bags = [bags] if isinstance(bags, Path) else list(bags)
    d = _load(bags)
    for msgs in d.values():
        msgs.sort(key=lambda tm: tm[0])
    if heartbeats is not None:
        heartbeats.extend(d.get("/diagnostics", []))
    summary: dict = {"bags": [str(b) for b in bags], "counts": {k: len(v) for k, v in d.items()}}
    summary.update(table1_rows(d, scene, series))
    summary["compliance"] = compliance_summary(d)
    summary["latency_ms"] = latency_hops(d)
    summary["faults"] = watchdog_faults(d)
    return summary


def _stroke_groups(tips: list, truths: list) -> tuple[dict[str, list], int]:
    """Valid fingertips grouped by the stroking segment the truth was playing at their exposure: key = moving
    time (``"10"``) for "stroke", ``"stroke_push_10"`` for "stroke_push"; and the number of invalid ones."""
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
            mt = f"{truth.moving_time:g}"
            groups[mt if truth.mode == "stroke" else f"stroke_push_{mt}"].append(m)
    return groups, n_invalid


def _is_paper(sc: Scene) -> bool:
    o, p = sc.object, paper_scene().object
    return o.kind == "cylinder" and bool(np.allclose([o.radius, o.length, *o.pose.position, *o.pose.rpy_deg],
                                                     [p.radius, p.length, *p.pose.position, *p.pose.rpy_deg],
                                                     rtol=0.0, atol=1e-9))


def table1_rows(d: dict[str, list], scene: Scene | None = None, series: dict | None = None) -> dict:
    """Table I rows (:func:`flexsheet.experiments.table1.scene_table1_row` on ``scene``, default the paper's
    cylinder; with ``paper`` for the paper's rows on the paper's cylinder) per stroking segment with ≥ 10
    fingertips inside the recorded sheet states, plus ``fingertip_invalid``, ``table1`` (felt and paper,
    :func:`felt_and_paper`, whose per-sample series go to ``series`` if given) and ``delay``
    (:func:`sheet_delay`); empty without ``/fingertip``, ``/world/finger`` and ``/world/sheet``. ``d``: topic →
    time-sorted (arrival s, message) pairs."""
    tips, truths, sheets = d.get("/fingertip", []), d.get("/world/finger", []), d.get("/world/sheet", [])
    if not (truths and sheets and tips):
        return {}
    groups, n_invalid = _stroke_groups(tips, truths)
    scene = scene if scene is not None else paper_scene()
    paper = _is_paper(scene)
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
    out["table1"] = felt_and_paper(d, groups, scene, s_ts, series)
    out["delay"] = sheet_delay(d, groups, scene)
    return out


def _interp_points(samples: list, t: np.ndarray, attr: str = "position") -> np.ndarray:
    ts = np.array([m.header.stamp for _, m in samples])
    v = np.array([getattr(m, attr) for _, m in samples], float)
    return np.stack([np.interp(t, ts, v[:, k]) for k in range(v.shape[1])], axis=1)


def _believed_sheet(d: dict[str, list], t: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """The sheet the display believes at times ``t``: its kinematics on the joint readback (the bridges'
    ``ArmJointState.pose``), both clamps interpolated, :func:`flexsheet.model.sheet.frame_from_clamps`."""
    from flexsheet.model.sheet import frame_from_clamps

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
                   series: dict | None = None) -> dict:
    """Table I two ways per stroking segment (issue 41):

    * ``felt``: the true fingertip (``/world/finger``, interpolated at each exposure) against the true sheet
      (``/world/sheet``): the row of :func:`flexsheet.experiments.table1.scene_table1_row` plus
      ``angle3d_mean_deg`` (the full 3-D angle between the object's normal at the true contact and the
      sheet's normal);
    * ``paper``: the paper's own measurement: the measured fingertip against the sheet the display believes
      (its kinematics on the joint readback).

    Plus ``decomposition`` per segment (:func:`_decomposition`: tremor, camera, prediction, kinematics),
    ``targets`` (Δθ mean, deg: the paper's ÷ :data:`~flexsheet.experiments.table1.FELT_TARGET_FACTOR`
    felt, ÷ :data:`~flexsheet.experiments.table1.TARGET_FACTOR` paper) and ``verdicts`` (met/MISSED) for the
    paper's rows. ``series``, if given, receives per segment the exposure times (s from the segment's first)
    and the per-sample Δθ (deg) of both, for the chart.
    """
    from flexsheet.planning.shape import planner_shape

    truths, sheets = d.get("/world/finger", []), d.get("/world/sheet", [])
    shape = planner_shape(scene)
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
    out["targets"] = {kind: {k: target(k, f)["dtheta_mean_deg"] for k in PAPER_TABLE1}
                      for kind, f in (("felt", FELT_TARGET_FACTOR), ("paper", TARGET_FACTOR))}
    out["verdicts"] = {f"{kind}.{k}": ("met" if out[kind][k]["dtheta_mean_deg"] <= out["targets"][kind][k]
                                       else "MISSED")
                       for kind in ("felt", "paper") for k in PAPER_TABLE1 if k in out[kind]}
    return out


#: the finger's slow motion is its 0.21 s moving average (21 samples at the world's 100 Hz): the rest is tremor
TREMOR_WINDOW = 21


def _normals(shape, points: np.ndarray) -> np.ndarray:
    """The object's unit normals (N, 3) at the points of ``shape`` nearest ``points`` (N, 3) m."""
    return np.array([shape.project(tuple(p)).normal for p in points])


def _angles_deg(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Angles (N,) deg between the unit directions (N, 3) ``a`` and ``b`` (sign-blind, as normals of a plane)."""
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


#: lags tried by :func:`sheet_delay`, s
DELAY_LAGS = np.arange(-0.030, 0.150001, 0.001)


def sheet_delay(d: dict[str, list], groups: dict[str, list], scene: Scene) -> dict:
    """How late the true sheet is, measured: the lag L (s) that best aligns the true sheet's normal at t with
    the object's normal at the true fingertip at t − L (least mean angle, over :data:`DELAY_LAGS`, on the
    fastest stroke, the 10 s one, where a lag costs the most angle; else the longest segment). The prediction already leads by its horizon h (``Fingertip.prediction_horizon``),
    so the delay from an exposure to the sheet at its pose is h + L: the value the horizon should have.
    Returns ``{"segment", "horizon_ms", "residual_lag_ms", "exposure_to_sheet_ms", "angle_at_best_deg"}``,
    or {} without the topics."""
    from flexsheet.planning.shape import planner_shape

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
    return {"segment": key, "horizon_ms": h * 1e3, "residual_lag_ms": best[1] * 1e3,
            "exposure_to_sheet_ms": (h + best[1]) * 1e3, "angle_at_best_deg": best[0]}


def _pct(x: np.ndarray) -> dict:
    return {"median": float(np.median(x)), "min": float(np.min(x)), "max": float(np.max(x)),
            "p5": float(np.percentile(x, 5)), "p95": float(np.percentile(x, 95))}


def compliance_summary(d: dict[str, list]) -> dict:
    """The tension the planner set at the contacts (``/sheet/target`` while ``touching``): ``all`` and per
    stroking segment (keys as the Table I rows, by the ``/world/finger`` truth at the target's fingertip
    exposure), each ``{"n", "tension_n_per_m", "stiffness_n_per_m", "object_stiffness_n_per_m"`` (median,
    min, max, p5, p95) ``, "at_limit"`` (share with ``object_stiffer_than_sheet`` / ``object_softer_than_sheet``
    in the status)``}``; empty without touching targets."""
    tg = [m for _, m in d.get("/sheet/target", []) if m.touching and not m.status.startswith("hold")]
    if not tg:
        return {}

    def block(ms: list) -> dict:
        return {"n": len(ms), "tension_n_per_m": _pct(np.array([m.tension for m in ms])),
                "stiffness_n_per_m": _pct(np.array([m.stiffness for m in ms])),
                "object_stiffness_n_per_m": _pct(np.array([m.object_stiffness for m in ms])),
                "at_limit": float(np.mean([("stiffer_than_sheet" in m.status) or ("softer_than_sheet" in m.status)
                                           for m in ms]))}

    out: dict = {"all": block(tg)}
    truths = d.get("/world/finger", [])
    if truths:
        tt = np.array([m.header.stamp for _, m in truths])
        groups: dict[str, list] = defaultdict(list)
        for m in tg:
            k = int(np.searchsorted(tt, m.source_stamp, side="right")) - 1
            if k < 0:
                continue
            tr = truths[k][1]
            if tr.phase == tr.mode and tr.mode in STROKE_MODES:
                mt = f"{tr.moving_time:g}"
                groups[mt if tr.mode == "stroke" else f"stroke_push_{mt}"].append(m)
        out.update({k: block(v) for k, v in groups.items() if len(v) >= 5})
    return out


#: a clamp at its commanded pose: position and rotation tolerance (m, rad)
POSE_TOL_M, POSE_TOL_RAD = 1e-4, np.radians(0.05)


def _at_pose(T: np.ndarray, G: np.ndarray) -> bool:
    if np.linalg.norm(T[:3, 3] - G[:3, 3]) > POSE_TOL_M:
        return False
    c = (np.trace(T[:3, :3].T @ G[:3, :3]) - 1.0) / 2.0
    return float(np.arccos(np.clip(c, -1.0, 1.0))) <= POSE_TOL_RAD


def _pose_times(d: dict[str, list]) -> dict[float, float]:
    """Source stamp → the time both clamps were first at that sample's arm targets (module doc)."""
    out: dict[float, float] = {}
    per_arm = []
    for arm in ("left", "right"):
        goals = {m.source_stamp: m.pose for _, m in d.get(f"/arm/{arm}/target", [])}
        reached: dict[float, float] = {}
        for _, m in sorted(d.get(f"/arm/{arm}/joint_state", []), key=lambda tm: tm[1].header.stamp):
            e = m.target_stamp
            if e and e not in reached and e in goals and _at_pose(m.pose, goals[e]):
                reached[e] = m.header.stamp
        per_arm.append(reached)
    for e in set(per_arm[0]) & set(per_arm[1]):
        out[e] = max(per_arm[0][e], per_arm[1][e])
    return out


def latency_hops(d: dict[str, list]) -> dict[str, dict]:
    """Latency chains (module doc), ms: ``{"chain": {hop: {"median", "p99", "n"}}, "sheet_at_pose_reached":
    share}``, matched through the stamps every message carries. ``d``: topic → (arrival s, message) pairs."""
    from flexsheet.twin.timing import LAB

    tips = {m.exposure_stamp: m for _, m in d.get("/fingertip", []) if m.sent_stamp and m.frame_stamp}
    target = {}
    for _, m in d.get("/sheet/target", []):
        target.setdefault(m.source_stamp, m.header.stamp)
    first_write: dict[float, float] = {}
    for topic in ("/arm/left/joint_state", "/arm/right/joint_state"):
        for _, m in d.get(topic, []):
            e = m.target_stamp
            if e and m.write_stamp and (e not in first_write or m.write_stamp < first_write[e]):
                first_write[e] = m.write_stamp
    at_pose = _pose_times(d)
    deform = {}
    for _, m in d.get("/object/deformation", []):
        deform.setdefault(m.source_stamp, m.header.stamp)
    render = {}
    for _, m in d.get("/render/stereo", []):
        render.setdefault(m.source_stamp, m.header.stamp)
    arm = [e for e in tips if e in target and e in first_write]
    rend = [e for e in tips if e in deform and e in render]
    hops = {
        "exposure_to_camera_frame": [tips[e].frame_stamp - e for e in tips],
        "camera_frame_to_fingertip": [tips[e].sent_stamp - tips[e].frame_stamp for e in tips],
        "fingertip_to_sheet_target": [target[e] - tips[e].sent_stamp for e in tips if e in target],
        "sheet_target_to_arm_command": [first_write[e] - target[e] for e in arm],
        "arm_command_to_sheet_at_pose": [at_pose[e] - first_write[e] for e in arm if e in at_pose],
        "exposure_to_arm_command": [first_write[e] - e for e in arm],
        "exposure_to_sheet_at_pose": [at_pose[e] - e for e in arm if e in at_pose],
        "fingertip_to_deformation": [deform[e] - tips[e].sent_stamp for e in tips if e in deform],
        "deformation_to_rendered_frame": [render[e] - deform[e] for e in rend],
        "rendered_to_projected": [LAB.projected_at(render[e]) - render[e] for e in rend],
        "exposure_to_projected": [LAB.projected_at(render[e]) - e for e in rend],
    }
    reached = sum(e in at_pose for e in arm) / len(arm) if arm else None
    return {"chain": {k: _stats(v) for k, v in hops.items()}, "sheet_at_pose_reached": reached}


def watchdog_faults(d: dict[str, list]) -> dict:
    """Watchdog trips over the run, from the controllers' status the bridges publish in ``/arm/<arm>/joint_state``:
    a trip is a state with ``fault == FAULT_WATCHDOG`` after one without (per arm, in stamp order; each is a hold
    and a fault on a real controller). Returns ``{"watchdog": total, "watchdog_per_arm": {arm: n}}``."""
    from messages.registers import FAULT_WATCHDOG

    per_arm = {}
    for arm in ("left", "right"):
        prev, n = 0, 0
        for _, m in sorted(d.get(f"/arm/{arm}/joint_state", []), key=lambda tm: tm[1].header.stamp):
            if m.fault == FAULT_WATCHDOG and prev != FAULT_WATCHDOG:
                n += 1
            prev = m.fault
        per_arm[arm] = n
    return {"watchdog": sum(per_arm.values()), "watchdog_per_arm": per_arm}


def cpu_summary(out_dir: Path) -> dict | None:
    """Per-node CPU (% of one core) from ``$(out)/cpu.json``, written by the Supervisor at stop (steady state: from
    10 s after each process started; a node in a container counts only its handler and timer threads, the
    container's total is under ``process_percent``). ``None`` when the file is absent or unreadable."""
    cpu_file = out_dir / "cpu.json"
    if not cpu_file.exists():
        return None
    try:
        cpu = json.loads(cpu_file.read_text())
        return {"wall_s": cpu["wall_s"], "cores": cpu["cores"],
                "node_percent": {n: v.get("steady_cpu_percent", v["cpu_percent"]) for n, v in cpu["nodes"].items()},
                "process_percent": {p: v.get("steady_cpu_percent", v["cpu_percent"])
                                    for p, v in cpu["processes"].items()},
                "note": cpu["note"]}
    except (OSError, ValueError, KeyError):
        return None


#: hop of the chain → (the node whose work it is, the topic it publishes: one output per call)
HOP_NODES = {"camera_frame_to_fingertip": ("triangulator", "/fingertip"),
             "fingertip_to_sheet_target": ("planner", "/sheet/target"),
             "fingertip_to_deformation": ("fem", "/object/deformation")}


def compute_vs_waiting(summary: dict, out_dir: Path) -> dict:
    """Wall clock: each hop's median split into its node's own compute per call (the node's CPU seconds over
    the run, ``cpu.json`` / ``cpu_<container>.json``, divided by its outputs) and the rest (waiting: queues,
    wake-ups, the other processes). A node in a container counts its handler threads only; a node alone its
    whole process (decoding and loop included: an upper bound). ms; empty where a figure is missing."""
    cpu: dict[str, float] = {}
    try:
        for f in out_dir.glob("cpu_*.json"):
            for n, v in json.loads(f.read_text()).get("nodes", {}).items():
                cpu[n] = float(v.get("handler_cpu_s", 0.0))
        for n, v in json.loads((out_dir / "cpu.json").read_text()).get("nodes", {}).items():
            cpu.setdefault(n, float(v.get("cpu_s", 0.0)))
    except (OSError, ValueError):
        return {}
    out = {}
    for hop, (node, topic) in HOP_NODES.items():
        n = summary["counts"].get(topic, 0)
        med = summary["latency_ms"]["chain"].get(hop, {}).get("median")
        if node in cpu and n and med is not None:
            c = 1e3 * cpu[node] / n
            out[hop] = {"node": node, "compute_ms": c, "waiting_ms": med - c, "median_ms": med}
    if out:
        out["note"] = ("compute_ms: the node's mean CPU per output (all its handlers); waiting_ms: the hop's median "
                       "minus it (negative where the node's other handlers make the mean exceed the median)")
    return out


def twin_settings(lf=None) -> dict:
    """``{"realism", "truth_seed", "source"}`` of the twin a launch ran: the launch file's top-level ``twin``
    (a mapping or a model), else the world node's ``twin`` param, else the world's defaults (``source`` says
    which). ``lf``: the :class:`flexsheet.runtime.launch.LaunchFile` (or ``None``)."""
    from flexsheet.twin.truth_choice import TruthChoice

    def as_dict(x) -> dict | None:
        if x is None:
            return None
        if hasattr(x, "model_dump"):
            return x.model_dump()
        return dict(x) if isinstance(x, dict) else None

    twin = lf.section("twin") if lf is not None and hasattr(lf, "section") else None
    found, source = as_dict(twin), "launch file twin section"
    if found is None and lf is not None:
        for spec in getattr(lf, "nodes", {}).values():
            if getattr(spec, "type", None) == "world":
                found, source = as_dict((spec.params or {}).get("twin")), "world node params"
                break
    if found is None:
        found, source = {}, "world node defaults (the launch file names no twin)"
    tp = TruthChoice(**{k: v for k, v in found.items() if k in TruthChoice.model_fields})
    return {"realism": tp.realism, "truth_seed": tp.truth_seed, "source": source}


def scene_settings(lf=None, out: str | None = None) -> tuple[Scene, dict]:
    """The scene a launch ran and its summary entry ``{"name", "file", "kind", "description", "source"}``: the
    launch file's top-level ``scene`` (substituted; ``--set scene=FILE`` lands there), else the world node's
    ``scene`` param, else the paper's cylinder (``source`` says which). An unreadable file is reported in
    ``source`` and the paper's cylinder used (the report never fails on it)."""
    path, source = None, "the paper's cylinder (the launch file names no scene)"
    scene = lf.section("scene") if lf is not None and hasattr(lf, "section") else None
    if scene:
        from flexsheet.runtime.launch import substitute, substitutions

        path, source = os.path.expanduser(substitute(scene, substitutions(lf, out))), "launch file scene"
    elif lf is not None:
        for spec in getattr(lf, "nodes", {}).values():
            if getattr(spec, "type", None) == "world" and (spec.params or {}).get("scene"):
                path, source = str(spec.params["scene"]), "world node params"
                break
    sc = paper_scene()
    if path:
        try:
            sc = load_scene(path)
        except ValueError as exc:
            source = f"{source}: unreadable ({str(exc).splitlines()[0][:200]}); the paper's cylinder used"
            path = None
    return sc, {"name": sc.name, "file": str(Path(path).resolve()) if path else None, "kind": sc.object.kind,
                "description": sc.description, "source": source}


def _charts(summary: dict, out: Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    keys = [k for k in ("10", "30") if k in summary]
    if keys:
        fig, ax = plt.subplots(1, 2, figsize=(9, 3.5))
        x = np.arange(len(keys))
        for a, (q, label) in zip(ax, (("dd", "Δd (mm)"), ("dtheta", "Δθ (deg)")), strict=True):
            unit = "mm" if q == "dd" else "deg"
            ours = [summary[k][f"{q}_mean_{unit}"] for k in keys]
            paper = [PAPER_TABLE1[k][f"{q}_mean_{unit}"] for k in keys]
            a.bar(x - 0.2, paper, 0.4, label="paper (Table I)")
            a.bar(x + 0.2, ours, 0.4, yerr=[summary[k][f"{q}_std_{unit}"] for k in keys], label="flexsheet (full graph)")
            a.set_xticks(x, [f"{k} s" for k in keys])
            a.set_ylabel(label)
            a.set_xlabel("moving time")
        ax[0].legend(fontsize=8)
        fig.tight_layout()
        fig.savefig(out / "table1.png", dpi=120)
        plt.close(fig)
    lat = {k: v for k, v in summary["latency_ms"].get("chain", {}).items() if v["n"]}
    if lat:
        fig, ax = plt.subplots(figsize=(8, 3.5))
        names = list(lat)
        ax.barh(names, [lat[k]["median"] for k in names], label="median")
        ax.scatter([lat[k]["p99"] for k in names], names, color="k", marker="|", s=200, label="p99")
        ax.set_xlabel("latency (ms), from the nodes' own stamps")
        ax.set_title("latency per hop and end to end (median, p99)")
        ax.legend(fontsize=8)
        fig.tight_layout()
        fig.savefig(out / "latency.png", dpi=120)
        plt.close(fig)


def felt_chart(summary: dict, series: dict, path: Path) -> dict:
    """The felt error against its target: Δθ per exposure over each stroking segment (felt: true finger vs
    true sheet; paper: measured finger vs believed sheet) with the target lines, and the segment means side by
    side. Writes ``path`` (PNG) and the same numbers as JSON beside it; returns that dict."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    t1 = summary.get("table1", {})
    keys = [k for k in ("10", "30", "stroke_push_10") if k in series and k in t1.get("felt", {})]
    data = {"title": "Table I felt (true finger vs true sheet) and paper (measured finger vs believed sheet)",
            "unit": "deg", "targets": t1.get("targets", {}), "verdicts": t1.get("verdicts", {}),
            "delay": summary.get("delay", {}),
            "means": {k: {"felt": t1["felt"][k]["dtheta_mean_deg"],
                          "paper": t1.get("paper", {}).get(k, {}).get("dtheta_mean_deg")} for k in keys},
            "series": {k: series[k] for k in keys}}
    if not keys:
        return data
    fig, axes = plt.subplots(1, len(keys) + 1, figsize=(4.2 * (len(keys) + 1), 3.6))
    tg = t1.get("targets", {})
    for ax, k in zip(axes, keys, strict=False):
        sr = series[k]
        ax.plot(sr["t_s"], sr["felt_deg"], lw=0.6, label="felt")
        if "paper_deg" in sr:
            ax.plot(sr["t_s"], sr["paper_deg"], lw=0.5, alpha=0.6, label="paper")
        row = k if k in PAPER_TABLE1 else k.rsplit("_", 1)[-1]
        for kind, style in (("felt", "--"), ("paper", ":")):
            if row in tg.get(kind, {}):
                ax.axhline(tg[kind][row], color="k", ls=style, lw=0.8, label=f"{kind} target (mean)")
        ax.set_title(f"{k} s: felt mean {data['means'][k]['felt']:.3f}°", fontsize=9)
        ax.set_xlabel("time in segment (s)")
        ax.set_ylabel("Δθ (deg)")
        ax.legend(fontsize=7)
    ax = axes[-1]
    x = np.arange(len(keys))
    ax.bar(x - 0.2, [data["means"][k]["felt"] for k in keys], 0.4, label="felt")
    ax.bar(x + 0.2, [data["means"][k]["paper"] or 0.0 for k in keys], 0.4, label="paper")
    for i, k in enumerate(keys):
        for kind, dx, m in (("felt", -0.2, "v"), ("paper", 0.2, "^")):
            if k in tg.get(kind, {}):
                ax.scatter([i + dx], [tg[kind][k]], color="k", marker=m, zorder=3)
    ax.set_xticks(x, [f"{k} s" for k in keys], fontsize=7)
    ax.set_ylabel("Δθ mean (deg); markers: targets")
    verdict = ", ".join(f"{k} {v}" for k, v in data["verdicts"].items())
    ax.set_title("felt vs paper\n" + verdict, fontsize=7)
    ax.legend(fontsize=7)
    fig.suptitle(data["title"], fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    path.with_suffix(".json").write_text(json.dumps(data))
    return data


def graph_chart(heartbeats: list, path: Path) -> dict:
    """Draw the live node/topic graph from recorded heartbeats (each node's last one): nodes on the left and
    right, topics in the middle, an arrow per publisher and subscription. Writes ``path`` (PNG) and
    returns the graph as ``{"nodes": {name: {"host", "publishes", "subscribes"}}}`` (also saved as JSON)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    last: dict = {}
    for _, hb in heartbeats:
        last[hb.node] = hb
    graph = {"nodes": {n: {"host": hb.host, "type": hb.node_type,
                           "publishes": sorted(p.topic for p in hb.publishers if p.topic != "/diagnostics"),
                           "subscribes": sorted(sub.topic for sub in hb.subscriptions)}
                       for n, hb in sorted(last.items())}}
    topics = sorted({t for v in graph["nodes"].values() for t in v["publishes"] + v["subscribes"]})
    names = list(graph["nodes"])
    fig, ax = plt.subplots(figsize=(11, max(4.0, 0.42 * max(len(topics), len(names)))))
    ty = {t: i for i, t in enumerate(reversed(topics))}
    ny = {n: i * (len(topics) - 1) / max(1, len(names) - 1) for i, n in enumerate(reversed(names))}
    for n, v in graph["nodes"].items():
        ax.text(0.0, ny[n], f"{n}\n[{v['host']}]", ha="center", va="center", fontsize=8,
                bbox={"boxstyle": "round", "fc": "#dbe9f6"})
        ax.text(2.0, ny[n], n, ha="center", va="center", fontsize=8, bbox={"boxstyle": "round", "fc": "#dbe9f6"})
        for t in v["publishes"]:
            ax.annotate("", (0.85, ty[t]), (0.18, ny[n]), arrowprops={"arrowstyle": "->", "color": "#1f77b4", "lw": 0.7})
        for t in v["subscribes"]:
            ax.annotate("", (1.82, ny[n]), (1.15, ty[t]), arrowprops={"arrowstyle": "->", "color": "#ff7f0e", "lw": 0.7})
    for t in topics:
        ax.text(1.0, ty[t], t, ha="center", va="center", fontsize=8, bbox={"boxstyle": "square", "fc": "#fff3d6"})
    ax.set_xlim(-0.4, 2.4)
    ax.set_ylim(-1, len(topics))
    ax.axis("off")
    ax.set_title("flexsheet node/topic graph (from the recorded heartbeats): publishers → topics → subscribers",
                 fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    path.with_suffix(".json").write_text(json.dumps(graph, indent=2))
    return graph


def _cell(v: float | None, width: int) -> str:
    """A table cell: ``v`` to 3 decimals, or "-" where the row has no such value (Δd 2R on a shape with no
    radius: the rounded box, the organ)."""
    return f"{'-':>{width}}" if v is None else f"{v:{width}.3f}"


def _format(summary: dict) -> str:
    tw = summary.get("twin", {})
    sc = summary.get("scene", {})
    lines = ["Table I — position and angle errors in stroking (full process graph, from the bag)",
             f"scene: {sc.get('name', 'cylinder')} ({sc.get('file') or sc.get('source', 'paper')})",
             f"twin: {tw.get('realism', '?')}, truth seed {tw.get('truth_seed', '?')} ({tw.get('source', '?')})",
             DD_CONVENTION, "",
             f"{'moving time':<16}{'Δθ mean deg':>12}{'Δθ std deg':>11}{'Δd 2R mm':>10}{'Δd R mm':>9}"
             f"{'paper Δθ':>10}{'paper Δd':>10}{'target Δθ':>10}{'n':>7}"]
    for key in sorted(k for k in summary if k[:1].isdigit() or k.startswith("stroke_push")):
        r = summary[key]
        p = r.get("paper", {})
        tg = target(key)["dtheta_mean_deg"] if key in PAPER_TABLE1 and p else float("nan")
        lines.append(f"{key + ' s':<16}{r['dtheta_mean_deg']:12.3f}{r['dtheta_std_deg']:11.3f}"
                     f"{_cell(r.get('dd_2r_mean_mm'), 10)}{r['dd_mean_mm']:9.3f}"
                     f"{p.get('dtheta_mean_deg', float('nan')):10.3f}{p.get('dd_mean_mm', float('nan')):10.3f}"
                     f"{tg:10.3f}{r['n']:7d}")
    t1 = summary.get("table1", {})
    if t1.get("felt"):
        lines += ["", "Table I, felt (true finger vs true sheet) and paper (measured finger vs believed sheet), deg/mm",
                  f"{'segment':<16}{'felt Δθ':>9}{'felt 3-D':>10}{'felt gap':>10}{'paper Δθ':>10}"]
        for key, r in t1["felt"].items():
            pr = t1.get("paper", {}).get(key, {})
            lines.append(f"{key:<16}{r['dtheta_mean_deg']:9.3f}{r['angle3d_mean_deg']:10.3f}{r['gap_mean_mm']:10.3f}"
                         f"{pr.get('dtheta_mean_deg', float('nan')):10.3f}")
        for key, dc in t1.get("decomposition", {}).items():
            lines.append(f"  {key}: made of (mean angle, deg) " + ", ".join(f"{k} {v:.3f}" for k, v in dc.items()))
        for k, v in t1.get("verdicts", {}).items():
            kind, row = k.split(".")
            lines.append(f"  {k}: Δθ mean {t1[kind][row]['dtheta_mean_deg']:.3f} deg, target "
                         f"{t1['targets'][kind][row]:.3f}: {v}")
    dl = summary.get("delay", {})
    if dl:
        lines += ["", f"Delay exposure -> sheet at its pose: {dl['exposure_to_sheet_ms']:.1f} ms (prediction horizon "
                      f"{dl['horizon_ms']:.1f} ms + residual lag {dl['residual_lag_ms']:.1f} ms, segment {dl['segment']})"]
    comp = summary.get("compliance", {})
    if comp:
        lines += ["", "Sheet tension at the contacts (/sheet/target while touching), median [p5, p95]",
                  f"{'segment':<16}{'tension N/m':>22}{'presented k N/m':>22}{'requested k N/m':>22}{'at limit':>9}"]
        for key, b in comp.items():
            f = "{0[median]:7.1f} [{0[p5]:5.1f},{0[p95]:6.1f}]".format
            lines.append(f"{key:<16}{f(b['tension_n_per_m']):>22}{f(b['stiffness_n_per_m']):>22}"
                         f"{f(b['object_stiffness_n_per_m']):>22}{b['at_limit']:9.0%}")
    lines += ["", "Latency per hop and end to end, from the nodes' stamps (ms)",
              f"{'hop':<32}{'median':>9}{'p99':>9}{'n':>7}"]
    for k, v in summary["latency_ms"].get("chain", {}).items():
        med = "-" if v["median"] is None else f"{v['median']:.2f}"
        p99 = "-" if v["p99"] is None else f"{v['p99']:.2f}"
        lines.append(f"{k:<32}{med:>9}{p99:>9}{v['n']:>7}")
    return "\n".join(lines)


def main(out: str, lf=None) -> int:
    """Analyse the bag in ``out`` (called by ``flexsheet launch`` after the run). Returns 0, or 1 without data."""
    out_dir = Path(out)
    bags = sorted((p for p in out_dir.glob("*.mcap") if not p.name.startswith("replay")),
                  key=lambda p: p.stat().st_mtime)
    if not bags:
        print(f"[report] no bag in {out_dir}", flush=True)
        return 1
    beats: list = []
    series: dict = {}
    scene, scene_entry = scene_settings(lf, out)
    summary = analyse(bags, beats, scene, series)
    summary["scene"] = scene_entry
    summary["twin"] = twin_settings(lf)
    clock = out_dir / "sim_clock.json"
    if clock.exists():   # a clock: sim run (flexsheet.runtime.container writes it)
        sim = json.loads(clock.read_text())
        summary["clock"] = "sim"
        summary["realtime_factor"] = sim.get("realtime_factor")
        summary["readiness"] = {f"{k}_active_s": v for k, v in sim.get("active_wall_s", {}).items()}
        summary["sim_clock"] = sim
    else:
        summary["clock"] = "wall"
    summary["seed"] = summary["twin"].get("truth_seed")
    if summary["clock"] == "wall":
        summary["latency_ms"]["compute_vs_waiting"] = compute_vs_waiting(summary, out_dir)
    cpu = cpu_summary(out_dir)
    if cpu is not None:
        summary["cpu"] = cpu
    summary["dd_convention"] = DD_CONVENTION
    (out_dir / "summary.json").write_text(json.dumps(summary, indent=2))
    _charts(summary, out_dir)
    felt_chart(summary, series, out_dir / "felt.png")
    if beats:
        graph_chart(beats, out_dir / "graph.png")
    text = _format(summary)
    (out_dir / "report.md").write_text("# flexsheet simulated run\n\n```\n" + text + "\n```\n\n"
                                       "![Table I](table1.png)\n\n![felt](felt.png)\n\n![latency](latency.png)\n\n"
                                       "![graph](graph.png)\n")
    print(text, flush=True)
    print(f"[report] wrote {out_dir}/summary.json, report.md, table1.png, felt.png, latency.png "
          f"(from {', '.join(b.name for b in bags)})", flush=True)
    return 0 if any(k[:1].isdigit() for k in summary) else 1


if __name__ == "__main__":
    sys.exit(main(sys.argv[1]))
