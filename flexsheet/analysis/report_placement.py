"""Where the true sheet stands against the object's surface while the finger touches it, from a run's bag
(pure; no transport): an encountered-type display promises the surface is there before the finger lands.

Per touching sample, the true sheet's signed distance ahead of (+) or behind (−) the object's surface under
the true fingertip, mm; per touch (a contiguous contact episode), the time from the finger's arrival at the
object's surface to the sheet's, ms. Read from ``/world/finger``, ``/world/sheet`` and ``/world/contact`` (the
twin's truth: this is the judge, not an estimator) and the scene's shape. Units: m, s; mm / ms only in report
values.

A sheet that yields to the viewer's head is not a placement error: while the planner's plan in force says
``keep_out`` (:class:`flexsheet.planning.head_guard.HeadGuard` backed the sheet off a head leaning into its
keep-out volume) and until the true sheet is back at the object's surface under the finger (at most
:data:`YIELD_MAX` s after the last such plan), a touching sample counts in ``head_yield`` and not in the
distance verdict (``distance_mm_all`` keeps every sample). A lost head (``hold:head_lost``) holds the pose
without backing off, so it is judged like any other sample.
"""

from __future__ import annotations

import numpy as np

from flexsheet.analysis.report_softness import MAX_GAP, episodes, object_surface
from flexsheet.planning.shape import planner_shape

__all__ = ["PLACEMENT_P99_MM", "SHEET_FIRST_TARGET", "ARRIVAL_TOL", "ARRIVAL_ANGLE_DEG", "ONSET_TARGET",
           "ARRIVAL_LOOKBACK", "YIELD_MAX", "placement"]

#: the true sheet may stand at most this far (mm, p99 of |distance|) ahead of or behind the object's surface
PLACEMENT_P99_MM = 2.0
#: the share of touches whose sheet must be at the object's surface before the finger
SHEET_FIRST_TARGET = 0.99
#: the sheet is "at" the object's surface when at most this far (m) behind it and at most
#: :data:`PLACEMENT_P99_MM` ahead (a sheet farther ahead is a wall in the air, not the object's surface)
ARRIVAL_TOL = 0.0005
#: the sheet is "at" the object's surface only when it is also within this angle (deg) of the object's tangent
#: plane under the finger: a sheet in place but still turning is not the surface the finger expects
ARRIVAL_ANGLE_DEG = 5.0
#: the share of landings (every touch onset, re-touches too) whose sheet is at the surface, in place and in
#: pose, when the finger arrives
ONSET_TARGET = 0.95
#: how far back (s) before the finger's arrival a sheet's wait is measured
ARRIVAL_LOOKBACK = 1.0
#: a yield to the head ends at the latest this long (s) after the last keep_out
#: plan (the slowest return measured on the shipped scenes, seed 0, took 2.2 s)
YIELD_MAX = 3.0


def _sheet_at(d: dict[str, list], t: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """The true sheet's plane at stamps ``t`` (N,) s: (origin (N, 3) m, unit normal (N, 3)), interpolated in
    ``/world/sheet``; None without two sheet samples."""
    sheets = sorted((m for _, m in d.get("/world/sheet", [])), key=lambda m: m.header.stamp)
    if len(sheets) < 2:
        return None
    ts = np.array([m.header.stamp for m in sheets])
    org = np.array([m.origin for m in sheets], float)
    nrm = np.array([m.normal for m in sheets], float)
    o = np.stack([np.interp(t, ts, org[:, k]) for k in range(3)], axis=1)
    n = np.stack([np.interp(t, ts, nrm[:, k]) for k in range(3)], axis=1)
    return o, n / np.linalg.norm(n, axis=1, keepdims=True)


def _crossing(t: np.ndarray, y: np.ndarray, i: int) -> float:
    """The time y crosses 0 upward between samples i − 1 and i (linear), t[i] at the first sample."""
    if i <= 0 or not np.isfinite(y[i - 1]) or y[i] == y[i - 1]:
        return float(t[i])
    return float(t[i - 1] + (t[i] - t[i - 1]) * (0.0 - y[i - 1]) / (y[i] - y[i - 1]))


def _world_touch(d: dict[str, list], t: np.ndarray) -> np.ndarray:
    """(N,) bool: the world's ``/world/contact`` touching at stamps ``t`` (nearest sample within MAX_GAP
    s)."""
    contacts = sorted(((m.header.stamp, m.touching) for _, m in d.get("/world/contact", [])))
    if not contacts:
        return np.zeros(len(t), bool)
    tc = np.array([c[0] for c in contacts])
    on = np.array([c[1] for c in contacts], bool)
    k = np.clip(np.searchsorted(tc, t), 0, len(tc) - 1)
    km = np.clip(k - 1, 0, len(tc) - 1)
    k = np.where(np.abs(tc[km] - t) < np.abs(tc[k] - t), km, k)
    return on[k] & (np.abs(tc[k] - t) <= MAX_GAP)


def _arrivals(t: np.ndarray, inside: np.ndarray, ahead: np.ndarray, cos: np.ndarray,
              runs) -> tuple[list[float], int, int, list[tuple[bool, float]]]:
    """Per landing of the finger on the object (a run of samples in it, within the touches ``runs``, index
    ranges) the sheet's arrival − the finger's, s (:func:`placement`); the counts of landings whose sheet
    never arrived and of touches the finger never pushed into the object; and per landing (whether the sheet
    was there at the finger's arrival, its angle to the object's tangent plane there, deg). ``cos``: the
    cosine between the object's and the sheet's normals per sample."""
    # ≥ 0: the sheet is at the surface, in place; `there` also in pose
    band = np.minimum(ahead + ARRIVAL_TOL, PLACEMENT_P99_MM * 1e-3 - ahead)
    there = (band >= 0.0) & (cos >= np.cos(np.radians(ARRIVAL_ANGLE_DEG)))
    angle = np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))
    arrivals, never, no_arrival, onsets = [], 0, 0, []
    landings = []
    for a, b in runs:
        inn = [(a + i, a + j) for i, j in episodes(t[a:b], inside[a:b] >= 0.0)]
        if not inn:
            no_arrival += 1
        landings += inn
    for f, b in landings:
        tf = (_crossing(t, inside, f) if f > 0 and inside[f - 1] <= 0.0 and t[f] - t[f - 1] <= MAX_GAP
              else float(t[f]))
        onsets.append((bool(there[f]), float(angle[f])))
        if there[f]:
            i = f                                   # back to the start of the sheet's run at the surface
            while i > 0 and there[i - 1] and tf - t[i - 1] <= ARRIVAL_LOOKBACK and t[i] - t[i - 1] <= MAX_GAP:
                i -= 1
            crossed = i > 0 and np.isfinite(ahead[i - 1]) and not there[i - 1] and t[i] - t[i - 1] <= MAX_GAP
            arrivals.append((_crossing(t, band, i) if crossed else float(t[i])) - tf)
        else:
            g = next((i for i in range(f + 1, b) if there[i]), None)
            if g is None:
                never += 1
                arrivals.append(float(t[b - 1]) - tf)
            else:
                arrivals.append(_crossing(t, band, g) - tf)
    return arrivals, never, no_arrival, onsets


def _onset_summary(onsets: list[tuple[bool, float]]) -> dict:
    """Every landing's (sheet there in place and pose, angle deg) (:func:`_arrivals`) summed up: {n,
    in_place_and_pose (share, None without landings), angle_deg {median, max} or None, verdict (against
    :data:`ONSET_TARGET`)}."""
    if not onsets:
        return {"n": 0, "in_place_and_pose": None, "angle_deg": None, "verdict": "MISSED"}
    share, ang = float(np.mean([o[0] for o in onsets])), [o[1] for o in onsets]
    return {"n": len(onsets), "in_place_and_pose": share,
            "angle_deg": {"median": float(np.median(ang)), "max": float(np.max(ang))},
            "verdict": "met" if share >= ONSET_TARGET else "MISSED"}


def _plans_in_force(d: dict[str, list], t: np.ndarray) -> tuple[list, np.ndarray]:
    """The ``/sheet/target`` plans by stamp and, per stamp of ``t`` (N,) s, the index of the newest at or
    before it (−1 before the first)."""
    plans = sorted((m for _, m in d.get("/sheet/target", [])), key=lambda m: m.header.stamp)
    ts = np.array([m.header.stamp for m in plans], float)
    return plans, (np.searchsorted(ts, t, side="right") - 1 if plans else np.full(len(t), -1))


def _head_yield(plans: list, k: np.ndarray, t: np.ndarray, ahead: np.ndarray) -> np.ndarray:
    """(N,) bool: the samples at stamps ``t`` (N,) s that fall in a yield to the head (module doc): from a
    plan in force (``plans[k]``, :func:`_plans_in_force`) whose status names ``keep_out``, until the true
    sheet is again at most :data:`ARRIVAL_TOL` behind the object's surface under the finger (``ahead`` (N,) m,
    NaN where not measured) or :data:`YIELD_MAX` s have passed since the last such plan."""
    out = np.zeros(len(t), bool)
    keep_out = np.array(["keep_out" in m.status for m in plans], bool)
    last = -np.inf                                  # stamp of the newest keep_out plan in force so far
    for i in range(len(t)):
        if k[i] >= 0 and keep_out[k[i]]:
            out[i], last = True, float(t[i])
        elif i > 0 and out[i - 1] and t[i] - last <= YIELD_MAX:
            out[i] = not (np.isfinite(ahead[i]) and ahead[i] >= -ARRIVAL_TOL)
    return out


def _split(plans: list, k: np.ndarray, o: np.ndarray, ns: np.ndarray, q: np.ndarray, cos: np.ndarray,
           miss: np.ndarray) -> dict | None:
    """The distance of the missed samples (``miss`` (N,) bool) split into three additive terms along the
    object's normal (÷ cos, as the distance): ``arms`` the true sheet's plane (``o``, ``ns`` (N, 3)) off the
    plan's pose (its ``sheet_origin``), ``plan_pose`` the plan's pose off its own contact (a limited or held
    plan) and ``contact`` the planned contact off the object's surface under the true finger (``q`` (N, 3)).
    Returns {n, median_mm {arms, plan_pose, contact}, share {…}: each term's sum ÷ the distance's sum (they
    add to 1)}, or
    None without a missed sample under a plan."""
    use = miss & (k >= 0)
    if not use.any():
        return None
    kk = k[use]
    so = np.array([plans[j].sheet_origin for j in kk], float)
    cp = np.array([plans[j].contact_point for j in kk], float)
    n_, c = ns[use], cos[use]
    terms = {"arms": np.einsum("ij,ij->i", o[use] - so, n_) / c,
             "plan_pose": np.einsum("ij,ij->i", so - cp, n_) / c,
             "contact": np.einsum("ij,ij->i", cp - q[use], n_) / c}
    total = sum(terms.values())
    den = float(total.sum())
    return {"n": int(use.sum()), "median_mm": {name: float(np.median(v)) * 1e3 for name, v in terms.items()},
            "share": {name: (float(v.sum()) / den if den else None) for name, v in terms.items()}}


def _spread(e: np.ndarray) -> dict:
    """{p50, p99, max} of |e| for a non-empty (N,) array."""
    a = np.abs(e)
    return {"p50": float(np.median(a)), "p99": float(np.percentile(a, 99)), "max": float(a.max())}


def placement(d: dict[str, list], scene) -> dict:
    """Where the true sheet stands against the object's surface while the finger touches (module doc).

    On the ``/world/finger`` samples (the true fingertip, stamps s) with the true sheet's plane interpolated
    there (``/world/sheet``): the object's surface under the finger (:func:`object_surface` of ``scene``, a
    :class:`flexsheet.model.scenes.Scene`) and the signed distance of the sheet's plane from it along the
    object's normal, + ahead, − behind (none where the normals are more than 78° apart). A sample touches when
    the finger is inside the object or behind the sheet's plane with ``/world/contact`` touching (within
    :data:`MAX_GAP` s); a touch is a contiguous run of them (:func:`episodes`). Samples in a yield to the head
    (:func:`_head_yield`) count in ``head_yield``, not in ``distance_mm``, ``by_phase_mm``, ``signed_mm``. Per
    landing (a run with the finger in the object) the finger arrives when its indentation crosses 0; the sheet
    is there when within :data:`ARRIVAL_TOL` behind to :data:`PLACEMENT_P99_MM` ahead of the surface and
    :data:`ARRIVAL_ANGLE_DEG` of its tangent plane. ``arrival_ms`` = sheet's arrival − finger's: negative, the
    sheet waited (at most :data:`ARRIVAL_LOOKBACK` s back); positive, late (a sheet that never arrives: the
    rest of the landing, counted in ``never``); a touch never pushed in has no arrival
    (``no_finger_arrival``).

    Returns ``{}`` without a scene, the finger, the sheet or a touching sample, else ``n`` (the judged
    touching samples), ``distance_mm`` {p50, p99, max} of |distance| (None when every sample yielded: "no
    verdict"), ``distance_mm_all`` (every measured touching sample), ``head_yield`` {n, share}, ``split``
    (:func:`_split`), ``by_phase_mm``, ``signed_mm`` {median, p1, p99}, ``touches``, ``arrivals``,
    ``sheet_first`` (their share with arrival_ms ≤ 0), ``late``, ``never``, ``no_finger_arrival``,
    ``arrival_ms`` {median, p99, max}, ``onsets`` (:func:`_onset_summary`: every landing in place and pose at
    the finger's arrival), ``targets``, ``verdicts`` {distance, sheet_first, onsets} and ``verdict`` (MISSED
    if any is)."""
    fingers = sorted((m for _, m in d.get("/world/finger", []) if m.phase != "paused"),
                     key=lambda m: m.header.stamp)
    if scene is None or len(fingers) < 2:
        return {}
    t = np.array([m.header.stamp for m in fingers], float)
    x = np.array([m.position for m in fingers], float)
    plane = _sheet_at(d, t)
    if plane is None:
        return {}
    o, ns = plane
    q, n, dist = object_surface(planner_shape(scene), x)
    inside = -dist                                                  # the object's indentation, m
    cos = np.einsum("ij,ij->i", n, ns)
    c = np.where(cos > 0.2, cos, 1.0)                               # the normal's share; 1 where not measured
    ahead = np.where(cos > 0.2, np.einsum("ij,ij->i", o - q, ns) / c, np.nan)
    behind_sheet = np.einsum("ij,ij->i", o - x, ns) > 0.0
    touching = (inside > 0.0) | (behind_sheet & _world_touch(d, t))
    runs = episodes(t, touching)
    if not runs:
        return {}
    arrivals, never, no_arrival, onsets = _arrivals(t, inside, ahead, cos, runs)
    judged = touching & np.isfinite(ahead)
    if not judged.any():
        return {}
    plans, k = _plans_in_force(d, t)
    keep = judged & ~(yielded := _head_yield(plans, k, t, ahead))
    e_all = ahead[judged] * 1e3
    e = ahead[keep] * 1e3
    phases = np.array([m.phase for m in fingers])[keep]
    by_phase = {p: {"n": int(np.sum(phases == p)), **_spread(e[phases == p])}
                for p in sorted(set(phases.tolist()))}
    arr = np.array(arrivals) * 1e3
    first = float(np.mean(arr <= 0.0)) if arr.size else None
    dist_mm, dist_all = (_spread(e) if e.size else None), _spread(e_all)
    on = _onset_summary(onsets)
    verdicts = {"distance": "no verdict" if dist_mm is None else
                ("met" if dist_mm["p99"] <= PLACEMENT_P99_MM else "MISSED"),
                "sheet_first": "met" if first is not None and first >= SHEET_FIRST_TARGET else "MISSED",
                "onsets": on.pop("verdict")}
    n_yield = int(np.sum(judged & yielded))
    return {"n": int(keep.sum()), "distance_mm": dist_mm, "distance_mm_all": dist_all,
            "head_yield": {"n": n_yield, "share": n_yield / int(judged.sum())}, "by_phase_mm": by_phase,
            "split": _split(plans, k, o, ns, q, c, keep & (np.abs(ahead) * 1e3 > PLACEMENT_P99_MM)),
            "signed_mm": ({"median": float(np.median(e)), "p1": float(np.percentile(e, 1)),
                           "p99": float(np.percentile(e, 99))} if e.size else None),
            "touches": len(runs), "arrivals": int(arr.size), "sheet_first": first,
            "late": int(np.sum(arr > 0.0)), "never": never, "no_finger_arrival": no_arrival,
            "arrival_ms": ({"median": float(np.median(arr)), "p99": float(np.percentile(arr, 99)),
                            "max": float(arr.max())} if arr.size else None),
            "onsets": on, "targets": {"distance_mm.p99": PLACEMENT_P99_MM, "sheet_first": SHEET_FIRST_TARGET,
                        "arrival_tol_mm": ARRIVAL_TOL * 1e3, "arrival_angle_deg": ARRIVAL_ANGLE_DEG,
                        "onsets": ONSET_TARGET},
            "verdicts": verdicts,
            "verdict": "MISSED" if "MISSED" in verdicts.values() else "met"}
