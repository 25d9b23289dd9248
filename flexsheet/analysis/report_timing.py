"""Latency, compliance, faults and CPU of a recorded run (parts of :mod:`flexsheet.analysis.report`).

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
  :meth:`flexsheet.model.timing.LabTiming.projected_at`); end: ``exposure_to_projected``.

On the simulated clock every hop is *modelled*: the lab's declared timings (:mod:`flexsheet.model.timing`)
charged to simulated time; on the wall clock the hops are *measured* on the host (:func:`latency_basis`).
All hosts of the sim run share one clock; across PCs see docs/deploy.md on time sync.
"""

from __future__ import annotations

import json
import re
from collections import defaultdict
from pathlib import Path

import numpy as np

from flexsheet.analysis.table1 import STROKE_MODES, segment_key
from flexsheet.model.timing import LAB
from messages.registers import FAULT_WATCHDOG

__all__ = ["latency_hops", "latency_basis", "compliance_summary", "planner_scales", "planner_gains",
           "watchdog_faults",
           "cpu_summary", "compute_vs_waiting", "POSE_TOL_M", "POSE_TOL_RAD", "HOP_NODES"]

#: a clamp at its commanded pose: position and rotation tolerance (m, rad)
POSE_TOL_M, POSE_TOL_RAD = 1e-4, np.radians(0.05)

#: hop → what the simulated clock charges for it (flexsheet/model/timing.py)
_MODELLED = {
    "exposure_to_camera_frame": "half the exposure + sensor readout + USB3 transfer + hand-over",
    "camera_frame_to_fingertip": "the triangulator's declared compute",
    "fingertip_to_sheet_target": "the planner's declared compute",
    "sheet_target_to_arm_command": "network + the bridge's declared IK, then its stream cycle",
    "arm_command_to_sheet_at_pose": "controller cycle + the controller twin's servo",
    "exposure_to_arm_command": "sum of the hops above it",
    "exposure_to_sheet_at_pose": "sum of the arm chain",
    "fingertip_to_deformation": "the FEM's declared compute",
    "deformation_to_rendered_frame": "the renderer's declared compute and frame pacing",
    "rendered_to_projected": "projector vsync + input latency",
    "exposure_to_projected": "sum of the render chain",
}


def _stats(x) -> dict:
    x = np.asarray(x, dtype=float) * 1e3
    if x.size == 0:
        return {"median": None, "p99": None, "n": 0}
    return {"median": float(np.median(x)), "p99": float(np.percentile(x, 99)), "n": int(x.size)}


def latency_basis(clock: str) -> dict[str, dict]:
    """Per hop ``{"basis": "modelled" | "measured", "how"}``: on ``clock`` "sim" every hop is modelled
    (declared lab timings, :mod:`flexsheet.model.timing`); on the wall clock measured from the nodes' stamps,
    but the projector (vsync and input latency), which is always modelled."""
    out = {}
    for hop, how in _MODELLED.items():
        if clock == "sim" or hop == "rendered_to_projected":
            out[hop] = {"basis": "modelled", "how": how}
        elif hop == "exposure_to_projected":
            out[hop] = {"basis": "measured", "how": "the nodes' stamps on this host; the projector modelled"}
        else:
            out[hop] = {"basis": "measured", "how": "the nodes' stamps on this host's clock"}
    return out


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
    deform, render = {}, {}
    for _, m in d.get("/object/deformation", []):
        deform.setdefault(m.source_stamp, m.header.stamp)
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


def _pct(x: np.ndarray) -> dict:
    return {"median": float(np.median(x)), "min": float(np.min(x)), "max": float(np.max(x)),
            "p5": float(np.percentile(x, 5)), "p95": float(np.percentile(x, 95))}


#: the planner's heartbeat message names a scale other than 1 as "x 0.5 (stiffness_scale)" (nodes/planner)
_SCALE = re.compile(r"\bx ([0-9.eE+-]+) \(stiffness_scale[),]")
_GAIN = re.compile(r"\bcontrast_gain ([0-9.eE+-]+)")


def _from_heartbeats(d: dict[str, list], pattern: re.Pattern) -> list[tuple[float, float]]:
    """(arrival s, value) from each planner heartbeat in ``/diagnostics`` that names its stiffness source
    (``stiffness: …``): ``pattern``'s first group, 1 without a match; in arrival order."""
    out = []
    for t, hb in d.get("/diagnostics", []):
        if hb is None or getattr(hb, "node_type", "") != "planner" or "stiffness:" not in hb.message:
            continue
        m = pattern.search(hb.message)
        out.append((float(t), float(m.group(1)) if m else 1.0))
    return out


def planner_scales(d: dict[str, list]) -> list[tuple[float, float]]:
    """(arrival s, ``stiffness_scale``) from the planner's heartbeats ("x S (stiffness_scale…)"; none: 1)."""
    return _from_heartbeats(d, _SCALE)


def planner_gains(d: dict[str, list]) -> list[tuple[float, float]]:
    """(arrival s, ``contrast_gain``) from the planner's heartbeats ("contrast_gain G"; none: 1)."""
    return _from_heartbeats(d, _GAIN)


def scales_at(scales: list[tuple[float, float]], t: np.ndarray) -> np.ndarray:
    """The scale in force at arrival times ``t``: the last heartbeat's before, else the first; NaN without
    any."""
    if not scales:
        return np.full(len(t), np.nan)
    ts, v = np.array([s[0] for s in scales]), np.array([s[1] for s in scales])
    return v[np.clip(np.searchsorted(ts, t, side="right") - 1, 0, len(v) - 1)]


def _compliance_block(ms: list, scale: np.ndarray) -> dict:
    k_req = np.array([m.object_stiffness for m in ms])
    out = {"n": len(ms), "tension_n_per_m": _pct(np.array([m.tension for m in ms])),
           "stiffness_n_per_m": _pct(np.array([m.stiffness for m in ms])),
           "object_stiffness_n_per_m": _pct(k_req),
           "at_limit": float(np.mean([("stiffer_than_sheet" in m.status) or ("softer_than_sheet" in m.status)
                                      for m in ms])),
           "stiffness_scale": None, "object_stiffness_unscaled_n_per_m": None}
    if np.all(np.isfinite(scale)):
        out["stiffness_scale"] = sorted({float(s) for s in scale})
        out["object_stiffness_unscaled_n_per_m"] = _pct(k_req / scale)
    return out


def compliance_summary(d: dict[str, list]) -> dict:
    """The tension the planner set at the contacts (``/sheet/target`` while ``touching``): ``all`` and per
    stroking segment (keys as the Table I rows), each ``{"n", "tension_n_per_m", "stiffness_n_per_m"``
    (presented), ``"object_stiffness_n_per_m"`` (requested: the object's × ``stiffness_scale``; each median,
    min, max, p5, p95), ``"at_limit"`` (share the sheet could not present), ``"stiffness_scale"`` (the values
    in force, :func:`planner_scales`; None when not recorded), ``"object_stiffness_unscaled_n_per_m"``}``."""

    tg = [(t, m) for t, m in d.get("/sheet/target", []) if m.touching and not m.status.startswith("hold")]
    if not tg:
        return {}
    scale = scales_at(planner_scales(d), np.array([t for t, _ in tg]))
    out: dict = {"all": _compliance_block([m for _, m in tg], scale)}
    truths = d.get("/world/finger", [])
    if truths:
        tt = np.array([m.header.stamp for _, m in truths])
        groups: dict[str, list] = defaultdict(list)
        for i, (_, m) in enumerate(tg):
            k = int(np.searchsorted(tt, m.source_stamp, side="right")) - 1
            tr = truths[k][1] if k >= 0 else None
            if tr is not None and tr.phase == tr.mode and tr.mode in STROKE_MODES:
                groups[segment_key(tr)].append(i)
        out.update({k: _compliance_block([tg[i][1] for i in v], scale[v]) for k,
                    v in groups.items() if len(v) >= 5})
    return out


def watchdog_faults(d: dict[str, list]) -> dict:
    """Watchdog trips over the run, from the controllers' status the bridges publish in
    ``/arm/<arm>/joint_state``: a trip is a state with ``fault == FAULT_WATCHDOG`` after one without (per arm,
    in stamp order; each is a hold and a fault on a real controller). Returns
    ``{"watchdog": total, "watchdog_per_arm": {arm: n}}``."""
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
    """Per-node CPU (% of one core) from ``$(out)/cpu.json``, written by the Supervisor at stop (steady state:
    from 10 s after each process started; a node in a container counts only its handler and timer threads, the
    container's total is under ``process_percent``). ``None`` when the file is absent or unreadable."""
    cpu_file = out_dir / "cpu.json"
    if not cpu_file.exists():
        return None
    try:
        cpu = json.loads(cpu_file.read_text())
        return {"wall_s": cpu["wall_s"], "cores": cpu["cores"],
                "node_percent": {n: v.get("steady_cpu_percent", v["cpu_percent"]) for n,
                                 v in cpu["nodes"].items()},
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
        out["note"] = ("compute_ms: the node's mean CPU per output (all its handlers); waiting_ms: the hop's "
                       "median minus it (negative where the node's other handlers make the mean exceed the "
                       "median)")
    return out
