"""The viewer's head in a run, from its bag (pure; no transport): how well the eyes were tracked, what the
viewer saw of the image, and how far the sheet kept from the head.

* ``eye``: each valid ``/eye/pose`` against the twin's true eyes (``/world/head``, interpolated to the pose's
  stamp): the larger of the two eyes' errors, mm.
* ``view``: for each rendered pair (``/render/stereo``: the eyes it was corrected for), where each eye of the
  *true* viewer sees the object's points — on the true sheet (``/world/sheet``, its plane) at the moment the
  frame is on it (:meth:`flexsheet.model.timing.LabTiming.projected_at`) — against where they belong: both
  rays from the true eye, through the drawn point and through the object's point, meet the imaginary screen (x
  = 0); their distance in projector pixels (:data:`~flexsheet.model.geometry.PIXEL_ON_SCREEN`). The points:
  the object's surface vertices the true eye sees, the outline included. The same frames judged as if they had
  been drawn for the fixed V (``fixed``) give the comparison under the same head motion. This isolates the
  viewpoint: the sheet's own error (model, registration) is the correction experiment's.
* ``safety``: the true sheet's clearance from the true head's keep-out volume
  (:class:`flexsheet.planning.keepout.KeepOut` of the planner's defaults), its minimum and the samples inside
  (violations); the true sheet's fastest point speed while within the near distance.

Units: mm and px in the summary (labelled), m and s inside.
"""

from __future__ import annotations

import numpy as np

from flexsheet.model import geometry
from flexsheet.model.timing import LAB
from flexsheet.planning.keepout import KeepOut
from flexsheet.rendering.stereo_renderer import vertex_normals

__all__ = ["eye_summary", "view_summary", "safety_summary", "lost_summary", "head_series", "head_summary"]

TARGETS = {"eye_error_mm_median": 2.0, "view_error_px_median": 1.0, "view_error_px_p95": 2.0,
           "keepout_violations": 0, "max_speed_near_head_mps": 0.25}


def _interp(ts: np.ndarray, vals: np.ndarray, t: np.ndarray) -> np.ndarray:
    return np.stack([np.interp(t, ts, vals[:, k]) for k in range(vals.shape[1])], axis=1)


def _heads(d: dict) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None:
    h = [m for _, m in d.get("/world/head", [])]
    if len(h) < 2:
        return None
    return (np.array([m.header.stamp for m in h]), np.array([m.left for m in h]),
            np.array([m.right for m in h]),
            np.array([m.eye for m in h]))


def _stats(x: np.ndarray) -> dict:
    return {"median": float(np.median(x)), "p95": float(np.percentile(x, 95)), "max": float(np.max(x)),
            "n": len(x)}


def eye_summary(d: dict) -> dict:
    """``{"error_mm": {median, p95, max, n}, "valid_share", "target_mm",
    "verdict"}``, or ``{}`` without poses."""
    heads = _heads(d)
    poses = [m for _, m in d.get("/eye/pose", [])]
    if heads is None or not poses:
        return {}
    ts, L, R, _ = heads
    poses = [m for m in poses if ts[0] <= m.header.stamp <= ts[-1]]  # while the world says where the head is
    ok = [m for m in poses if m.valid]
    if not ok:
        return {"valid_share": 0.0, "verdict": "MISSED"}
    t = np.array([m.header.stamp for m in ok])
    el = np.linalg.norm(np.array([m.left for m in ok]) - _interp(ts, L, t), axis=1)
    er = np.linalg.norm(np.array([m.right for m in ok]) - _interp(ts, R, t), axis=1)
    s = _stats(np.maximum(el, er) * 1e3)
    return {"error_mm": s, "valid_share": len(ok) / len(poses), "target_mm": TARGETS["eye_error_mm_median"],
            "verdict": "met" if s["median"] <= TARGETS["eye_error_mm_median"] else "MISSED"}


def _screen(E: np.ndarray, X: np.ndarray) -> np.ndarray:
    """Where the rays from eye ``E`` (3,) through points ``X`` (N, 3) meet the imaginary screen x = 0: (N, 2)
    y, z."""
    s = E[0] / (E[0] - X[:, 0])
    return (E[None, 1:] + s[:, None] * (X[:, 1:] - E[None, 1:]))


def _on_plane(E: np.ndarray, X: np.ndarray, o: np.ndarray, n: np.ndarray) -> np.ndarray:
    """The points (N, 3) where the rays from ``E`` through ``X`` meet the plane (``o``, ``n``)."""
    D = X - E
    s = ((o - E) @ n) / (D @ n)
    return E + s[:, None] * D


def _seen(E: np.ndarray, V: np.ndarray, N: np.ndarray) -> np.ndarray:
    """Vertices ``V`` (N, 3) with normals ``N`` facing the eye ``E``, the outline included (cos ≥ −0.05)."""
    d = E - V
    return (np.einsum("ij,ij->i", N, d) / np.linalg.norm(d, axis=1)) >= -0.05


def _frame_errors(drawn_for: np.ndarray, true_eye: np.ndarray, V: np.ndarray, N: np.ndarray, o,
                  n) -> np.ndarray:
    """px errors of the points of one eye image drawn for ``drawn_for`` seen from ``true_eye`` (sheet plane o,
    n)."""
    m = _seen(true_eye, V, N)
    X = V[m]
    S = _on_plane(drawn_for, X, o, n)            # where the projector lights each point on the true sheet
    err = np.linalg.norm(_screen(true_eye, S) - _screen(true_eye, X), axis=1)
    return err / geometry.PIXEL_ON_SCREEN


def head_series(d: dict, vertices: np.ndarray, normals: np.ndarray, fixed_eyes: np.ndarray) -> dict | None:
    """Per rendered pair: ``t`` s, ``tracked``/``fixed`` (F, 2) median px error per eye and the per-point
    errors pooled per eye (``tracked_all``/``fixed_all``: two lists of arrays). ``fixed_eyes`` (2, 3) m: V ∓
    IPD/2. None without heads, sheets or frames."""
    heads = _heads(d)
    frames = [m for _, m in d.get("/render/stereo", []) if m.correction != "image"]
    sheets = [m for _, m in d.get("/world/sheet", [])]
    if heads is None or not frames or len(sheets) < 2:
        return None
    ts, L, R, _ = heads
    st = np.array([s.header.stamp for s in sheets])
    so, sn = np.array([s.origin for s in sheets]), np.array([s.normal for s in sheets])
    out = {"t": [], "tracked": [], "fixed": [], "source": [], "tracked_all": [[], []], "fixed_all": [[], []]}
    for f in frames:
        t = LAB.projected_at(f.header.stamp)
        if t > ts[-1] or t < ts[0]:
            continue
        true = [_interp(ts, L, np.array([t]))[0], _interp(ts, R, np.array([t]))[0]]
        o = _interp(st, so, np.array([t]))[0]
        n = _interp(st, sn, np.array([t]))[0]
        n /= np.linalg.norm(n)
        row_t, row_f = [], []
        for k in range(2):
            et = _frame_errors(np.asarray(f.eyes[k], float), true[k], vertices, normals, o, n)
            ef = _frame_errors(fixed_eyes[k], true[k], vertices, normals, o, n)
            out["tracked_all"][k].append(et)
            out["fixed_all"][k].append(ef)
            row_t.append(float(np.median(et)))
            row_f.append(float(np.median(ef)))
        out["t"].append(t)
        out["tracked"].append(row_t)
        out["fixed"].append(row_f)
        out["source"].append(f.eye_source)
    return out if out["t"] else None


def view_summary(series: dict | None) -> dict:
    """``{"tracked": {"left"/"right": {error_px_median, error_px_p95}, "error_px_median", "error_px_p95"},
    "fixed": {...}, "frames", "sources", "target", "verdict"}`` from :func:`head_series`; ``{}`` without
    it."""
    if series is None:
        return {}
    out: dict = {"frames": len(series["t"]),
                 "sources": {s: series["source"].count(s) for s in ("tracked", "held", "fixed")}}
    for kind in ("tracked", "fixed"):
        per = {}
        for k, eye in enumerate(("left", "right")):
            x = np.concatenate(series[f"{kind}_all"][k])
            per[eye] = {"error_px_median": float(np.median(x)), "error_px_p95": float(np.percentile(x, 95))}
        per["error_px_median"] = max(per["left"]["error_px_median"], per["right"]["error_px_median"])
        per["error_px_p95"] = max(per["left"]["error_px_p95"], per["right"]["error_px_p95"])
        out[kind] = per
    tr = out["tracked"]
    out["target"] = {"error_px_median": TARGETS["view_error_px_median"],
                     "error_px_p95": TARGETS["view_error_px_p95"]}
    out["verdict"] = ("met" if tr["error_px_median"] <= TARGETS["view_error_px_median"]
                      and tr["error_px_p95"] <= TARGETS["view_error_px_p95"] else "MISSED")
    return out


def safety_summary(d: dict, keepout: KeepOut | None = None) -> tuple[dict, dict]:
    """(summary, series) of the true sheet (its corners and edges) against the true head's keep-out: the
    summary ``{"min_head_distance_m"`` (the smallest clearance from the keep-out boundary, m), ``"margin_m"``,
    ``"keepout_violations"`` (sheet samples with a point inside), ``"max_speed_near_head_mps"`` (the fastest
    corner speed while within ``near_distance``), ``"targets"``, ``"verdict"}``; the series ``t``,
    ``clearance``."""
    ko = keepout or KeepOut()
    heads = _heads(d)
    sheets = [m for _, m in d.get("/world/sheet", [])]
    if heads is None or len(sheets) < 2:
        return {}, {}
    ts, _, _, E = heads
    t = np.array([s.header.stamp for s in sheets])
    C = np.array([s.corners for s in sheets])                              # (S, 4, 3)
    mids = 0.5 * (C + np.roll(C, -1, axis=1))
    pts = np.concatenate([C, mids, np.array([s.origin for s in sheets])[:, None]], axis=1)
    eyes = _interp(ts, E, t)
    centres = np.array([ko.center(e) for e in eyes])
    clear = np.linalg.norm(pts - centres[:, None], axis=2).min(axis=1) - ko.radius
    dt = np.diff(t)
    speed = np.zeros(len(t))
    good = dt > 1e-6
    sp = np.linalg.norm(np.diff(C, axis=0), axis=2).max(axis=1)
    speed[1:][good] = sp[good] / dt[good]
    near = clear < ko.near_distance
    out = {"min_head_distance_m": float(clear.min()) + ko.margin, "margin_m": ko.margin,
           "keepout_violations": int((clear < 0.0).sum()),
           "max_speed_near_head_mps": float(speed[near].max()) if near.any() else 0.0,
           "near_samples": int(near.sum()),
           "targets": {"keepout_violations": 0,
                       "max_speed_near_head_mps": TARGETS["max_speed_near_head_mps"]}}
    out["verdict"] = ("met" if out["keepout_violations"] == 0
                      and out["max_speed_near_head_mps"] <= TARGETS["max_speed_near_head_mps"] else "MISSED")
    return out, {"t": t.tolist(), "clearance_m": clear.tolist()}


def lost_summary(d: dict) -> dict:
    """The glasses lost (the script hides them: ``/world/head`` ``visible`` false): per span, how long after
    the first invalid ``/eye/pose`` the planner held (its first ``hold:head_lost`` target), the largest step
    of the sheet target's centre while it held (mm: nothing may jump), and the frames drawn for the held pose.
    ``{}`` without a span."""
    heads = [m for _, m in d.get("/world/head", [])]
    spans, start = [], None
    for m in heads:
        if not m.visible and start is None:
            start = m.header.stamp
        elif m.visible and start is not None:
            spans.append((start, m.header.stamp))
            start = None
    if not spans:
        return {}
    poses = [m for _, m in d.get("/eye/pose", [])]
    targets = [(t, m) for t, m in d.get("/sheet/target", [])]
    frames = [m for _, m in d.get("/render/stereo", [])]
    out = []
    for a, b in spans:
        bad = [m.header.stamp for m in poses if not m.valid and a <= m.header.stamp <= b + 0.1]
        held = [(m.header.stamp, m) for _, m in targets
                if "hold:head_lost" in m.status and a <= m.header.stamp <= b + 0.5]
        steps = [float(np.linalg.norm(q.sheet_origin - p.sheet_origin))
                 for (_, p), (_, q) in zip(held[:-1], held[1:], strict=True)]
        out.append({"start_s": a, "duration_s": b - a,
                    "hold_after_ms": 1e3 * (held[0][0] - bad[0]) if bad and held else None,
                    "hold_step_mm_max": 1e3 * max(steps) if steps else 0.0,
                    "frames_held": sum(1 for f in frames if f.eye_source == "held"
                                       and a <= f.header.stamp <= b + 0.1)})
    ok = all(o["hold_after_ms"] is not None and o["hold_after_ms"] <= 1e3 / 60.0
             and o["hold_step_mm_max"] < 0.1
             for o in out)
    return {"spans": out, "target": "hold within one head-camera period (16.7 ms), no step while held",
            "verdict": "met" if ok else "MISSED"}


def head_summary(d: dict, scene, series: dict | None = None) -> dict:
    """``{"eye", "view", "safety"}`` of a run's bag ``d`` (topic → [(log time, message)]) on ``scene`` (its
    surface mesh is the object judged); ``{}`` when the run had no head. The per-frame view errors and the
    clearance series go to ``series["head"]`` if given."""
    if not d.get("/world/head"):
        return {}
    V, F = scene.surface_mesh()[:2]
    V = np.asarray(V, float)
    N = vertex_normals(V, F).astype(float)
    frames = [m for _, m in d.get("/render/stereo", []) if m.correction != "image"]
    ipd = float(np.median([np.linalg.norm(m.eyes[1] - m.eyes[0]) for m in frames])) if frames else 0.064
    fixed = np.stack([geometry.EYE - [0.0, ipd / 2, 0.0], geometry.EYE + [0.0, ipd / 2, 0.0]])
    vs = head_series(d, V, N, fixed)
    safety, clear = safety_summary(d)
    if series is not None:
        series["head"] = {"view": vs, "clearance": clear}
    lost = lost_summary(d)
    if lost:
        safety["head_lost"] = lost
    return {"eye": eye_summary(d), "view": view_summary(vs), "safety": safety}
