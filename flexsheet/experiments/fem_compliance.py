"""The FEM's stiffness and the sheet's tension along a scene's stroke, from a launch run: where the planner
asked the sheet for more over an inclusion (:func:`compliance_along_stroke`). Run::

    python -m flexsheet.experiments.fem_compliance --scene launch/scenes/organ.yaml --run out/organ --out docs/figures/scenes
"""  # noqa: E501 - a table, template or command line kept whole

from __future__ import annotations

import argparse
import json
import os
import sys

import numpy as np

from flexsheet.model.scenes import load_scene
from flexsheet.runtime.bag_read import read_bag
from flexsheet.runtime.codec import decode_any

__all__ = ["compliance_along_stroke", "main"]


def compliance_along_stroke(run_dir: str, scene_path, out_dir: str, bin_mm: float = 2.5) -> dict:
    """From a launch run (``run_dir``/sim.mcap): the FEM's dF/dd (``/object/deformation``, valid, depth > 0)
    and the sheet's tension and requested stiffness (``/sheet/target`` while touching) binned by the contact
    point's position along the scene's stroke (arc length, mm; nearest of 400 path points), with each
    inclusion's place on the path (the path point nearest its centre). Writes
    ``fem_compliance_<scene>.png`` + ``.json`` into ``out_dir``; returns the numbers."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from scipy.spatial import cKDTree

    sc = load_scene(scene_path)
    bag = os.path.join(run_dir, "sim.mcap")
    pts, _ = sc.stroke_points(400)
    s_path = np.linspace(0.0, sc.stroke_length(), 400) * 1e3
    tree = cKDTree(pts)
    de = [m for m in (decode_any(x.frames) for x in read_bag(bag, topics=["/object/deformation"]))
          if m.valid and m.depth > 0 and m.scene_key == sc.key()]
    tg = [m for m in (decode_any(x.frames) for x in read_bag(bag, topics=["/sheet/target"]))
          if m.touching and not m.status.startswith("hold")]
    edges = np.arange(0.0, s_path[-1] + bin_mm, bin_mm)

    def binned(cp, v):
        if not len(cp):
            return [], []
        s = s_path[tree.query(np.asarray(cp))[1]]
        k = np.digitize(s, edges) - 1
        cen, med = [], []
        for b in range(len(edges) - 1):
            sel = k == b
            if sel.sum() >= 3:
                cen.append(float(0.5 * (edges[b] + edges[b + 1])))
                med.append(float(np.median(np.asarray(v)[sel])))
        return cen, med

    out = {"scene": sc.name, "run": run_dir, "bin_mm": bin_mm, "n_deformations": len(de),
           "n_targets": len(tg),
           "fem_stiffness_N_per_m": binned([m.contact_point for m in de], [m.stiffness for m in de]),
           "fem_depth_mm": binned([m.contact_point for m in de], [m.depth * 1e3 for m in de]),
           "tension_N_per_m": binned([m.contact_point for m in tg], [m.tension for m in tg]),
           "requested_stiffness_N_per_m": binned([m.contact_point for m in tg],
                                                 [m.object_stiffness for m in tg]),
           "inclusions_at_mm": [float(s_path[tree.query(np.asarray(i.center))[1]]) for i in sc.inclusions]}
    os.makedirs(out_dir, exist_ok=True)
    with open(os.path.join(out_dir, f"fem_compliance_{sc.name}.json"), "w") as fh:
        json.dump(out, fh, indent=1)
    fig, ax = plt.subplots(figsize=(8, 4.2))
    ax.plot(*out["fem_stiffness_N_per_m"], "o-", label="FEM dF/dd (N/m)")
    ax.plot(*out["tension_N_per_m"], "s-", label="sheet tension (N/m)")
    ax.plot(*out["requested_stiffness_N_per_m"], "^-", label="stiffness asked of the sheet (N/m)")
    for i, x in enumerate(out["inclusions_at_mm"]):
        ax.axvline(x, color="r", ls="--", lw=0.8, label="inclusion centre (nearest path "
                                                        "point)" if i == 0 else None)
    ax.set_xlabel("position along the stroke, mm")
    ax.set_ylabel("N/m")
    ax.set_title(f"{sc.name}: FEM stiffness and sheet tension along the stroke (medians per {bin_mm:g} mm)")
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(os.path.join(out_dir, f"fem_compliance_{sc.name}.png"), dpi=110)
    plt.close(fig)
    return out



def main(argv: list[str] | None = None) -> int:
    """CLI (see the module doc)."""
    ap = argparse.ArgumentParser(
        prog="python -m flexsheet.experiments.fem_compliance",
        description="The FEM's dF/dd and the sheet's tension along a scene's stroke, from a launch run's "
                    "sim.mcap.",
        epilog="example: python -m flexsheet.experiments.fem_compliance --scene launch/scenes/organ.yaml "
               "--run out/organ --out docs/figures/scenes")
    ap.add_argument("--scene", required=True, help="scene file (launch/scenes/*.yaml)")
    ap.add_argument("--run", required=True, help="a launch output folder (its sim.mcap)")
    ap.add_argument("--out", required=True, help="output folder")
    args = ap.parse_args(argv)
    try:
        c = compliance_along_stroke(args.run, args.scene, args.out)
    except (OSError, ValueError) as exc:
        print(f"fem_compliance: {exc}", file=sys.stderr)
        return 2
    print(json.dumps(c, indent=1)[:3000])
    return 0


if __name__ == "__main__":      # pragma: no cover
    sys.exit(main())
