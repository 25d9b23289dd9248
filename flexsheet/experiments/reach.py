"""``flexsheet experiment reach --draws N``: how much of each drawn object's stroke the two arms can present
at all, whatever the planner does.

The tangent plane at each point of a stroke fixes three of the sheet's six degrees of freedom; the in-plane
turn ψ and the contact's place on the sheet (s_u, s_v) are free (docs/objects.md). For each object (the
paper's cylinder, then the draws of :func:`flexsheet.model.scene_draw.write_scene`) the stroke's path
(:meth:`~flexsheet.model.scenes.Scene.stroke_at`: the task's path, what the target mark follows; no twin's
truth) is sampled at ``--samples`` points, and at each the sheet tangent there is tried:

* ``paper``: the paper's rule (ψ = 0, the contact at the sheet's centre);
* ``psi``: any ψ in ±90° every :data:`PSI_STEP_DEG`, the contact at the centre;
* ``any``: any ψ and any (s_u, s_v) on a grid of ±:data:`OFFSET_MAX` m every :data:`OFFSET_STEP` m.

A pose counts when both arms' IK (:class:`~flexsheet.planning.arm_reach.ArmReach`: the nominal bases, the
bridges' joint limits less their margin and the planner's slack) converges from the arms' home joints, the
last sample's solution or :data:`RANDOM_SEEDS` seeded random joints, at strain :data:`STRETCH`. The tilt is
the angle between the plane's normal and the home sheet's (+x). Writes ``reach.json`` (per object and
sample) and ``reach.png`` (the share of each stroke presentable three ways, the target 100 %); a stroke
not wholly presentable by any pose is the arms' floor, not the planner's. Units m, rad (degrees in the
JSON's ``*_deg`` and the chart); display frame.
"""

from __future__ import annotations

import argparse
import json
import logging
import math
import sys
from pathlib import Path

import numpy as np

from flexsheet.model import geometry
from flexsheet.model.scene_draw import write_scene
from flexsheet.model.scenes import Scene, load_scene_or_paper
from flexsheet.model.sheet import clamp_poses
from flexsheet.model.vec import perp_unit
from flexsheet.planning.arm_reach import ArmReach
from flexsheet.planning.planner_config import PlannerConfig
from flexsheet.planning.pose_choice import turn

__all__ = ["presentable", "stroke_reach", "main", "PSI_STEP_DEG", "OFFSET_MAX", "OFFSET_STEP", "STRETCH",
           "RANDOM_SEEDS"]

log = logging.getLogger(__name__)

#: deg between the ψ tried
PSI_STEP_DEG = 10.0
#: m: the contact's place on the sheet tried within ±this, every OFFSET_STEP m
OFFSET_MAX, OFFSET_STEP = 0.08, 0.04
#: engineering strain between the clamps of every pose tried (a light stroke's)
STRETCH = 0.04
#: random joint seeds tried after the home joints and the last solution
RANDOM_SEEDS = 3
#: the planner's defaults: the paper's reference axis ``u_ref`` and the sheet's size
PLANNER = PlannerConfig()


def presentable(reach: ArmReach, q: np.ndarray, n: np.ndarray, u: np.ndarray, offset: tuple[float, float],
                last: dict, rng_seed: int = 0) -> bool:
    """Whether both arms of ``reach`` solve the sheet tangent at ``q`` (3,) m with unit normal ``n`` (3,),
    axis ``u`` (3,) and the contact at ``offset`` (s_u, s_v) m on it (module doc: the seeds tried). ``last``
    {side: (6,) rad}: the last solutions, updated with these."""
    v = np.cross(n, u)
    o = q - offset[0] * u - offset[1] * v
    found = {}
    for side, T in zip(("left", "right"), clamp_poses(o, n, u, STRETCH, PLANNER.material.size),
                       strict=True):
        kin = reach.kin[side]
        rng = np.random.default_rng(rng_seed)
        seeds = [reach.seed[side]] + ([last[side]] if side in last else []) + [
            rng.uniform(kin.q_lower, kin.q_upper) for _ in range(RANDOM_SEEDS)]
        for s0 in seeds:
            r = kin.ik(T, s0, max_iter=60, max_jump=math.inf)
            if r.ok:
                found[side] = r.q
                break
        else:
            return False
    last.update(found)
    return True


def stroke_reach(scene: Scene, samples: int) -> dict:
    """The stroke of ``scene`` sampled at ``samples`` points (module doc): per sample the fraction, the
    tilt (deg), whether each of ``paper``, ``psi``, ``any`` presents it and the pose found; the shares."""
    reach = ArmReach({"left": geometry.LEFT_BASE, "right": geometry.RIGHT_BASE})
    pts, nrm = scene.stroke_at(np.linspace(0.0, 1.0, samples))
    psis = [math.radians(PSI_STEP_DEG * k) for k in range(int(90 / PSI_STEP_DEG) + 1)]
    psis = sorted({p for a in psis for p in (a, -a)}, key=abs)
    grid = np.arange(-OFFSET_MAX, OFFSET_MAX + 1e-9, OFFSET_STEP)
    offsets = sorted(((a, b) for a in grid for b in grid), key=lambda o: math.hypot(*o))
    rows, last = [], {}
    for f, q, n in zip(np.linspace(0.0, 1.0, samples), pts, nrm, strict=True):
        u0 = np.asarray(perp_unit(tuple(n), PLANNER.u_ref))
        paper = presentable(reach, q, n, u0, (0.0, 0.0), last)
        row = {"fraction": float(f), "tilt_deg": math.degrees(math.acos(float(np.clip(n[0], -1.0, 1.0)))),
               "paper": paper, "psi": paper, "any": paper, "pose": [0.0, 0.0, 0.0] if paper else None}
        found = None if paper else _first_pose(reach, q, n, u0, psis, offsets, last)
        if found is not None:
            psi, off = found
            row["any"], row["pose"], row["psi"] = True, [math.degrees(psi), off[0], off[1]], off == (0.0, 0.0)
        rows.append(row)
    share = {k: sum(r[k] for r in rows) / len(rows) for k in ("paper", "psi", "any")}
    ok = [r["tilt_deg"] for r in rows if r["any"]]
    return {"samples": rows, "share": share, "largest_tilt_presented_deg": max(ok) if ok else None,
            "largest_tilt_asked_deg": max(r["tilt_deg"] for r in rows)}


def _first_pose(reach: ArmReach, q: np.ndarray, n: np.ndarray, u0: np.ndarray, psis: list[float],
                offsets: list[tuple[float, float]], last: dict) -> tuple[float, tuple[float, float]] | None:
    """The first (ψ rad, (s_u, s_v) m) of ``offsets`` × ``psis``, nearest the centre first, other than the
    paper's pose, that :func:`presentable` accepts; None where none does."""
    for off in offsets:
        for p in psis:
            u = np.asarray(turn(tuple(n), tuple(u0), p))
            if (p, off) != (0.0, (0.0, 0.0)) and presentable(reach, q, n, u, off, last):
                return p, off
    return None


def chart(result: dict, path: Path) -> None:
    """Per object, the share of its stroke presentable by the paper's rule, by a turn ψ, by any pose (bars)
    against the target 100 % (``path``, PNG; the numbers are ``reach.json``)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = list(result["objects"])
    fig, ax = plt.subplots(figsize=(9, 4))
    x = np.arange(len(names))
    for i, (k, label) in enumerate((("paper", "paper's rule"), ("psi", "any ψ, contact at the centre"),
                                    ("any", "any ψ and contact place"))):
        ax.bar(x + (i - 1) * 0.27, [100 * result["objects"][m]["share"][k] for m in names], 0.27, label=label)
    ax.axhline(100, color="k", ls="--", lw=1.0, label="target: all of the stroke")
    ax.set_xticks(x, names, rotation=30, fontsize=8)
    ax.set_ylabel("share of the stroke presentable (%)")
    n_full = sum(result["objects"][m]["share"]["any"] == 1.0 for m in names)
    ax.set_title(f"Which strokes the two arms can present at all: {n_full}/{len(names)} wholly "
                 f"(verdict: {'met' if n_full == len(names) else 'MISSED by the arms'})", fontsize=9)
    ax.legend(fontsize=7, loc="lower left")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="flexsheet experiment reach", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter,
                                 epilog="example: flexsheet experiment reach --draws 6 --out "
                                        "docs/figures/objects/reach\n"
                                        "         flexsheet experiment reach --first 3 --draws 1 --samples 6 "
                                        "--out /tmp/reach")
    ap.add_argument("--out", required=True, help="output folder (reach.json, reach.png, draw<k>/)")
    ap.add_argument("--draws", type=int, default=8, help="how many drawn objects (default 8)")
    ap.add_argument("--first", type=int, default=0, help="seed of the first draw (default 0)")
    ap.add_argument("--samples", type=int, default=12, help="points along each stroke (default 12)")
    args = ap.parse_args(argv)
    if args.draws < 0 or args.samples < 2:
        ap.error(f"--draws must be >= 0 and --samples >= 2, got {args.draws} and {args.samples}")
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    out = Path(args.out).resolve()
    out.mkdir(parents=True, exist_ok=True)
    result = {"title": "Which strokes the two arms can present at all",
              "units": "share of the stroke's samples (0..1); tilt in deg from the home sheet's normal",
              "target": "1.0: every point of every stroke presentable by some pose", "samples": args.samples,
              "psi_step_deg": PSI_STEP_DEG,
              "offset_max_m": OFFSET_MAX,
              "offset_step_m": OFFSET_STEP, "stretch": STRETCH, "objects": {}}
    jobs = [("cylinder", None, "the paper's cylinder")] + [
        (f"draw{k}", write_scene(k, out / f"draw{k}"), None)
        for k in range(args.first, args.first + args.draws)]
    for i, (name, path, desc) in enumerate(jobs):
        desc = desc or path.read_text().splitlines()[0].lstrip("# ")
        print(f"[reach] {name} ({i + 1}/{len(jobs)}): {desc}", flush=True)
        r = stroke_reach(load_scene_or_paper(path), args.samples)
        result["objects"][name] = {"description": desc, **r}
        print(f"[reach] {name}: presentable {100 * r['share']['paper']:.0f} % by the paper's rule, "
              f"{100 * r['share']['psi']:.0f} % with a turn, {100 * r['share']['any']:.0f} % by any pose; "
              f"tilt asked up to {r['largest_tilt_asked_deg']:.1f} deg", flush=True)
        (out / "reach.json").write_text(json.dumps(result, indent=1))
    short = [n for n, o in result["objects"].items() if o["share"]["any"] < 1.0]
    result["verdict"] = "met" if not short else f"MISSED by the arms: {', '.join(short)}"
    (out / "reach.json").write_text(json.dumps(result, indent=1))
    chart(result, out / "reach.png")
    print(f"[reach] wrote {out / 'reach.json'} and reach.png", flush=True)
    print(f"[reach] not wholly presentable by any pose: {', '.join(short) or 'none'}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
