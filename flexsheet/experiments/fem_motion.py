"""What the eye notices as the finger moves, on the model the FEM node serves for a scene: the drawn dent
against the fingertip, and jumps of the surface from one frame to the next (:mod:`flexsheet.fem.eye_judge`),
along the scene's **stroke** (the finger at ``use.stroke_depth``, :data:`STROKE_STEP` of arc a frame) and its
**push** (at the stroke's middle, 0 → ``use.max_depth``, :data:`PUSH_STEP` of depth a frame). Every frame is
one ``update_finger`` of the served model, as the node runs it. :func:`served_motion` is called by
:func:`flexsheet.experiments.fem_scene.run_scene`; its blocks are ``contact`` and ``temporal`` in
summary.json.

Alone, without the reference solves the full judge needs (seconds, not hours):
``python -m flexsheet.experiments.fem_motion --scene launch/scenes/NAME.yaml --out DIR`` writes
``DIR/motion.json`` (the scene, the served model, its update time, ``contact`` and ``temporal``) and
``DIR/motion.png`` (the gap and the jump along the stroke and the push, with their targets and verdicts).
"""

from __future__ import annotations

import argparse
import json
import logging
import math
import os
import sys

import numpy as np

from flexsheet.fem.config import FemConfig
from flexsheet.fem.eye_judge import contact_gap, frame_jumps
from flexsheet.fem.served import launch_arc_deg, scene_update_ms, served_finger, served_model
from flexsheet.model.scenes import load_scene
from flexsheet.runtime.console import LIBRARY, show_lines

log = logging.getLogger("flexsheet.experiments.fem_motion")   # also when run as __main__

__all__ = ["served_motion", "motion_run", "main", "STROKE_STEP", "PUSH_STEP", "GAP_TARGET_PX",
           "JUMP_TARGET_PX"]

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
    log.info(f"{what}: {len(frames)} frames, gap {g_px.max():.2f} px ({g_mm.min():+.2f}..{g_mm.max():+.2f} "
             f"mm), jump p99 {np.percentile(jumps, 99):.2f} px, max {jumps[k]:.2f} px at frame {k + 1}")
    return {"frames": len(frames), "step_mm": step_mm, "methods": sorted(set(methods)),
            "gap_px_max": float(g_px.max()), "gap_mm_range": [float(g_mm.min()), float(g_mm.max())],
            "gap_px": g_px.tolist(), "jump_px_p99": float(np.percentile(jumps, 99)),
            "jump_px_max": float(jumps.max()), "jump_px_max_at_frame": k + 1, "jump_px": jumps.tolist()}


def served_motion(sc, rt) -> dict:
    """The served model ``rt`` (:func:`flexsheet.fem.served.served_model`) of scene ``sc`` along its stroke
    and its push (module doc). Returns {"contact": {"gap_px_max", "target_px", "stroke", "push", ...},
    "temporal": {"jump_px_p99", "target_px", ...}}; each of "stroke"/"push" holds its frames' ``gap_px`` (N,),
    ``jump_px`` (N − 3,), the signed gap range (mm) and the served methods."""
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
                    "metric": "the served surface's least distance to the fingertip sphere's centre less its "
                              "radius, as each eye sees it: the larger of its shift on the screen and its "
                              "change of disparity, px; flexsheet/fem/eye_judge.py",
                    "stroke": {k_: v for k_, v in stroke.items() if not k_.startswith("jump")},
                    "push": {k_: v for k_, v in push.items() if not k_.startswith("jump")}},
        "temporal": {"jump_px_p99": p99, "target_px": JUMP_TARGET_PX, "meets_target": p99 <= JUMP_TARGET_PX,
                     "jump_px_max": max(push["jump_px_max"], stroke["jump_px_max"]),
                     "metric": "per frame, the largest over the seen vertices and both eyes of the change to "
                               "the next frame less the mean of the changes around it (a second difference: "
                               "the reference's change is taken as smooth at frame rate), px; p99 over the "
                               "frames of the stroke and the push; flexsheet/fem/eye_judge.py",
                     "stroke": {k_: v for k_,
                                v in stroke.items() if k_.startswith("jump") or k_ in ("frames", "step_mm")},
                     "push": {k_: v for k_,
                              v in push.items() if k_.startswith("jump") or k_ in ("frames", "step_mm")}},
    }


def motion_run(scene_path, out_dir: str) -> dict:
    """Judge the served model of the scene file ``scene_path`` in motion (:func:`served_motion`) and time its
    update (:func:`flexsheet.fem.served.scene_update_ms`: 5 stroke points × 5 mm, the middle and the deepest
    declared depth, 20 calls each); write ``out_dir``/motion.json and motion.png; return the JSON's dict.
    Raises ``ValueError`` (:class:`flexsheet.model.scene_parts.SceneError`) for a bad scene file."""
    sc = load_scene(scene_path)
    rt, what = served_model(sc, FemConfig(arc_deg=launch_arc_deg(sc)))
    log.info(f"scene {sc.name!r}: served model: {what}")
    md = sc.use.max_depth
    timing = scene_update_ms(rt, sc, (0.005, 0.5 * md, md), 20)
    m = served_motion(sc, rt)
    c, t = m["contact"], m["temporal"]
    out = {"title": f"{sc.name}: the served surface in motion",
           "scene": {"name": sc.name, "file": str(scene_path)},
           "served": what, "units": {"gap": "px", "jump": "px", "update": "ms CPU"},
           "realtime": {"update_ms": timing["median"], "update_ms_p90": timing["p90"],
                        "methods": timing["methods"]},
           "contact": c, "temporal": t,
           "verdict": {"contact": "met" if c["meets_target"] else "MISSED",
                       "temporal": "met" if t["meets_target"] else "MISSED"}}
    os.makedirs(out_dir, exist_ok=True)
    with open(os.path.join(out_dir, "motion.json"), "w") as fh:
        json.dump(out, fh, indent=1)
    import matplotlib  # heavy, and only for the chart

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(10, 4))
    for ax, key, what_, target in ((axes[0], "gap_px", "contact", c["target_px"]),
                                   (axes[1], "jump_px", "temporal", t["target_px"])):
        for part, style in (("stroke", "-"), ("push", "--")):
            y = m[what_][part][key]
            ax.plot(np.arange(1, len(y) + 1), y, style, label=f"{part} ({m[what_][part]['step_mm']:.2f} mm a "
                                                              "frame)")
        ax.axhline(target, color="k", ls=":", lw=0.8, label=f"target {target} px")
        ax.set_xlabel("frame")
        ax.set_ylabel(f"{key.replace('_px', '')}, projector px")
        ax.set_title(f"{what_}: {out['verdict'][what_]}")
        ax.legend(fontsize=7)
    fig.suptitle(out["title"] + f" ({timing['median']:.2f} ms/update)")
    fig.tight_layout()
    fig.savefig(os.path.join(out_dir, "motion.png"), dpi=100)
    plt.close(fig)
    log.info(f"{sc.name}: contact gap {c['gap_px_max']:.2f} px (target {c['target_px']}), jump p99 "
             f"{t['jump_px_p99']:.2f} px (target {t['target_px']}), update {timing['median']:.3f} ms -> "
             f"{out_dir}")
    return out


def main(argv: list[str] | None = None) -> int:
    """CLI (see the module doc)."""
    ap = argparse.ArgumentParser(
        prog="python -m flexsheet.experiments.fem_motion",
        description="The FEM node's served surface as the finger strokes and presses: the drawn dent against "
                    "the fingertip and frame-to-frame jumps, in projector pixels (no reference solves).",
        epilog="example: python -m flexsheet.experiments.fem_motion --scene launch/scenes/organ.yaml "
               "--out docs/figures/scenes/organ")
    ap.add_argument("--scene", required=True, help="scene file (launch/scenes/*.yaml)")
    ap.add_argument("--out", required=True, help="output folder (motion.json, motion.png)")
    args = ap.parse_args(argv)
    show_lines(LIBRARY)
    try:
        motion_run(args.scene, args.out)
    except ValueError as exc:
        print(f"fem_motion: {exc}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":      # pragma: no cover
    sys.exit(main())
