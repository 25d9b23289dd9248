"""One-off (session 26; run from the repository root: ``python3
docs/figures/scenes/path_table_moves/contact_moves.py [--jobs 2]``): the shipped path tables' held-out pushes
served two ways, against the same held-out references — **moved** (each station's correction moved with the
contact before blending, what nodes/fem/path_snapshots.py serves since session 26) and **fixed** (the two
stations' corrections blended on fixed vertices, what it served in sessions 24–25) — and the linear model alone.

The held-out pushes are those of each scene's path_table.json (solved on their own meshes, as
flexsheet.experiments.path_table solves them, cached under ~/.cache/flexsheet/fem: the rounded box's three take
~25 min wall on two cores when the cache is empty). Visible rendered vertices only (not held, outside the
finger's footprint), as everywhere. Also the look-up's CPU time per update with the moved table and the linear
model's, as path_table.json times them. Writes contact_moves.json and contact_moves.png beside this file."""

import argparse
import json
import os
import sys

sys.path.insert(0, ".")
import numpy as np  # noqa: E402

from flexsheet.experiments import path_table as P  # noqa: E402
from flexsheet.experiments.fem_scene import _update_ms, visible_errors  # noqa: E402
from flexsheet.model.scenes import SCENES_DIR, load_scene  # noqa: E402
from nodes.fem.cache import DEFAULT_CACHE_DIR, ArrayCache  # noqa: E402
from nodes.fem.scene_model import SceneModel, attach_scene_table, finger_on_scene  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))
TARGET_MM = 0.7


def within_to(depths_mm, err):
    """The deepest depth (mm) up to which every error is within the target (0 when the first is not)."""
    out = 0.0
    for d, e in zip(depths_mm, err, strict=True):
        if e > TARGET_MM:
            break
        out = d
    return out


def scene(name: str, jobs: int) -> dict:
    sc = load_scene(SCENES_DIR / f"{name}.yaml")
    rep = json.load(open(f"docs/figures/scenes/{name}/path_table/path_table.json"))
    holdout = [h["fraction"] for h in rep["held_out"]]
    cache = ArrayCache(DEFAULT_CACHE_DIR, lambda m: print(f"[{name}] {m}", file=sys.stderr))
    rt = SceneModel(sc)
    kind, where = attach_scene_table(rt, cache)
    if kind != "path" or where is None:
        raise SystemExit(f"{name}: no path table found ({kind}, {where})")
    pt = rt.path_table
    verts = rt.rest_vertices.astype(float)
    held = rt.held
    P._prefetch(str(sc.source), [(h, P.GRID["h_fine"]) for h in holdout], DEFAULT_CACHE_DIR, jobs)
    depths = pt.depths[1:]
    C = pt.correction.astype(float)
    out = {"stations": len(pt.fractions), "table_from": where, "depths_mm": (depths * 1e3).tolist(), "held_out": []}
    for h in holdout:
        ref = P._push(sc, float(h), P.GRID["h_fine"], verts, cache)
        q, n = sc.stroke_at([h])
        q, n = q[0], n[0]
        u_ref = np.asarray(ref["u"])[:len(depths)]
        u_lin = P._linear(rt, sc, q, n, depths)[0]
        ups = [rt.update_finger(finger_on_scene(q, n, float(d), sc.finger.radius)) for d in depths]
        assert {up.method for up in ups} == {"path_snapshots"}, {up.method for up in ups}
        u_moved = np.stack([up.vertices.astype(float) - verts for up in ups])
        f, _ = pt.locate(q)
        i = int(np.clip(np.searchsorted(pt.fractions, f, side="right") - 1, 0, len(pt.fractions) - 2))
        a = (f - pt.fractions[i]) / (pt.fractions[i + 1] - pt.fractions[i])
        u_fixed = u_lin + (1 - a) * C[i, 1:] + a * C[i + 1, 1:]          # the table's depths are these depths
        u_fixed[:, held] = 0.0
        row = {"fraction": float(h), "between_stations": [float(pt.fractions[i]), float(pt.fractions[i + 1])],
               "weight": float(a)}
        for lab, u in (("moved", u_moved), ("fixed", u_fixed), ("linear", u_lin)):
            e = visible_errors(u, u_ref, verts, held, q, n, depths, sc.finger.radius)
            row[f"{lab}_mm"] = e
            row[f"{lab}_max_mm"] = max(e)
            row[f"{lab}_within_target_to_mm"] = within_to(out["depths_mm"], e)
        print(f"[{name}] held out {h:.4f}: moved {row['moved_max_mm']:.2f} mm (within to "
              f"{row['moved_within_target_to_mm']:g} mm), fixed {row['fixed_max_mm']:.2f} (to "
              f"{row['fixed_within_target_to_mm']:g}), linear {row['linear_max_mm']:.2f}", file=sys.stderr)
        out["held_out"].append(row)
    look = _update_ms(rt, sc, P.LOOKUP_DEPTHS, 200)            # as path_table.json's lookup_ms
    rt.path_table = None
    lin = _update_ms(rt, sc, P.LOOKUP_DEPTHS, 200)
    out.update({"lookup_ms": look["median"], "lookup_ms_p90": look["p90"], "lookup_methods": look["methods"],
                "linear_update_ms": lin["median"],
                "lookup_timing": "the updating thread's CPU per update_finger at 5 points x 5/20/45 mm along the "
                                 "stroke (flexsheet.experiments.fem_scene._update_ms), the moved table and then "
                                 "the linear model alone"})
    print(f"[{name}] look-up {look['median']:.3f} ms (p90 {look['p90']:.3f}), linear {lin['median']:.3f} ms",
          file=sys.stderr)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--scene", action="append", default=None, help="organ, rounded_box (default both)")
    a = ap.parse_args()
    res = {"what": __doc__.split("\n\n")[0].replace("\n", " "), "target_mm": TARGET_MM, "scenes": {}}
    for name in a.scene or ["organ", "rounded_box"]:
        res["scenes"][name] = scene(name, a.jobs)
    with open(os.path.join(HERE, "contact_moves.json"), "w") as fh:
        json.dump(res, fh, indent=1)
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axs = plt.subplots(1, len(res["scenes"]), figsize=(5.5 * len(res["scenes"]), 4.2), squeeze=False)
    for ax, (name, s) in zip(axs[0], res["scenes"].items(), strict=True):
        for k, h in enumerate(s["held_out"]):
            c = f"C{k}"
            ax.plot(s["depths_mm"], h["moved_mm"], "-o", ms=3, color=c, label=f"moved, {h['fraction']:.3f}")
            ax.plot(s["depths_mm"], h["fixed_mm"], "--", color=c, label=f"fixed vertices, {h['fraction']:.3f}")
            ax.plot(s["depths_mm"], h["linear_mm"], ":", color=c, alpha=0.6, label=f"linear, {h['fraction']:.3f}")
        ax.axhline(TARGET_MM, color="k", lw=0.8, ls=":")
        ax.set_ylim(0, 8)
        ax.set_xlabel("push depth (mm)")
        ax.set_ylabel("largest visible error (mm)")
        ax.set_title(f"{name}: held out, {s['stations']} stations")
        ax.legend(fontsize=6)
    fig.tight_layout()
    fig.savefig(os.path.join(HERE, "contact_moves.png"), dpi=110)
    print(f"wrote {os.path.join(HERE, 'contact_moves.json')}", file=sys.stderr)


if __name__ == "__main__":
    main()
