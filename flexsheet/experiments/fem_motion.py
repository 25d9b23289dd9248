"""What the eye notices as the finger moves, on the model the FEM node serves for a scene: the drawn dent against
the fingertip, and jumps of the surface from one frame to the next (:mod:`flexsheet.fem.eye_judge`), along the
scene's **stroke** (the finger at ``use.stroke_depth``, :data:`STROKE_STEP` of arc a frame) and its **push** (at
the stroke's middle, 0 → ``use.max_depth``, :data:`PUSH_STEP` of depth a frame). Every frame is one
``update_finger`` of the served model, as the node runs it. :func:`served_motion` is called by
:func:`flexsheet.experiments.fem_scene.run_scene`; its blocks are ``contact`` and ``temporal`` in summary.json.
"""

from __future__ import annotations

import logging
import math

import numpy as np

from flexsheet.fem.eye_judge import contact_gap, frame_jumps
from flexsheet.fem.served import served_finger

log = logging.getLogger(__name__)

__all__ = ["served_motion", "STROKE_STEP", "PUSH_STEP", "GAP_TARGET_PX", "JUMP_TARGET_PX"]

STROKE_STEP = 0.0005     #: m of stroke a frame: a 30 mm/s stroke rendered at 60 Hz
PUSH_STEP = 0.00025      #: m of depth a frame: a 15 mm/s press rendered at 60 Hz
GAP_TARGET_PX = 1.0      #: the dent meets the fingertip within a pixel
JUMP_TARGET_PX = 0.5     #: p99 of a frame's jump


def _frames(sc, rt, pts, nrm, depths) -> tuple[list[np.ndarray], list, list[str]]:
    fingers = [served_finger(sc, q, n, float(d)) for q, n, d in zip(pts, nrm, depths, strict=True)]
    ups = [rt.update_finger(f) for f in fingers]
    return [np.array(u.vertices, float) for u in ups], fingers, [u.method for u in ups]


def _judge(frames, fingers, faces, methods, step_mm: float, what: str) -> dict:
    gaps = [contact_gap(v, faces, f) for v, f in zip(frames, fingers, strict=True)]
    jumps = frame_jumps(frames, faces, fingers)
    g_px = np.array([g["gap_px"] for g in gaps])
    g_mm = np.array([g["gap_m"] for g in gaps]) * 1e3
    k = int(np.argmax(jumps))
    log.info(f"{what}: {len(frames)} frames, gap {g_px.max():.2f} px ({g_mm.min():+.2f}..{g_mm.max():+.2f} mm), "
             f"jump p99 {np.percentile(jumps, 99):.2f} px, max {jumps[k]:.2f} px at frame {k + 1}")
    return {"frames": len(frames), "step_mm": step_mm, "methods": sorted(set(methods)),
            "gap_px_max": float(g_px.max()), "gap_mm_range": [float(g_mm.min()), float(g_mm.max())],
            "gap_px": g_px.tolist(), "jump_px_p99": float(np.percentile(jumps, 99)),
            "jump_px_max": float(jumps.max()), "jump_px_max_at_frame": k + 1, "jump_px": jumps.tolist()}


def served_motion(sc, rt) -> dict:
    """The served model ``rt`` (:func:`flexsheet.fem.served.served_model`) of scene ``sc`` along its stroke and
    its push (module doc). Returns {"contact": {"gap_px_max", "target_px", "stroke", "push", ...}, "temporal":
    {"jump_px_p99", "target_px", ...}}; each of "stroke"/"push" holds its frames' ``gap_px`` (N,), ``jump_px``
    (N − 3,), the signed gap range (mm) and the served methods."""
    faces = np.asarray(rt.faces)
    q, n = sc.stroke_at([0.5])
    depths = np.arange(1, int(round(sc.use.max_depth / PUSH_STEP)) + 1) * PUSH_STEP
    fr, fg, me = _frames(sc, rt, np.repeat(q, len(depths), 0), np.repeat(n, len(depths), 0), depths)
    push = _judge(fr, fg, faces, me, PUSH_STEP * 1e3, "push")
    k = max(4, int(math.ceil(sc.stroke_length() / STROKE_STEP)) + 1)
    pts, nrm = sc.stroke_points(k)
    fr, fg, me = _frames(sc, rt, pts, nrm, np.full(k, sc.use.stroke_depth))
    stroke = _judge(fr, fg, faces, me, sc.stroke_length() / (k - 1) * 1e3, "stroke")
    gap = max(push["gap_px_max"], stroke["gap_px_max"])
    p99 = max(push["jump_px_p99"], stroke["jump_px_p99"])
    return {
        "contact": {"gap_px_max": gap, "target_px": GAP_TARGET_PX, "meets_target": gap <= GAP_TARGET_PX,
                    "stroke_depth_mm": sc.use.stroke_depth * 1e3, "push_to_mm": float(depths[-1] * 1e3),
                    "metric": "the served surface's least distance to the fingertip sphere's centre less its radius, "
                              "as each eye sees it: the larger of its shift on the screen and its change of "
                              "disparity, px; flexsheet/fem/eye_judge.py",
                    "stroke": {k_: v for k_, v in stroke.items() if not k_.startswith("jump")},
                    "push": {k_: v for k_, v in push.items() if not k_.startswith("jump")}},
        "temporal": {"jump_px_p99": p99, "target_px": JUMP_TARGET_PX, "meets_target": p99 <= JUMP_TARGET_PX,
                     "jump_px_max": max(push["jump_px_max"], stroke["jump_px_max"]),
                     "metric": "per frame, the largest over the seen vertices and both eyes of the change to the "
                               "next frame less the mean of the changes around it (a second difference: the "
                               "reference's change is taken as smooth at frame rate), px; p99 over the frames of "
                               "the stroke and the push; flexsheet/fem/eye_judge.py",
                     "stroke": {k_: v for k_, v in stroke.items() if k_.startswith("jump") or k_ in ("frames", "step_mm")},
                     "push": {k_: v for k_, v in push.items() if k_.startswith("jump") or k_ in ("frames", "step_mm")}},
    }
