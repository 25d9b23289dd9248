"""``flexsheet experiment compliance --out DIR``: the stiffness the sheet can present, the scene's mapped into
it, and whether a palpating finger can still feel the organ's tumour.

1. **The presentable range** at the sheet's centre (:mod:`flexsheet.model.tension`: k = T·w·(1/a + 1/b)), between
   the least stretch (1 %) and the first of two limits:

   * **what the arms can pull**: the RV-1A's rated payload, 1 kg (Mitsubishi BFP-A8050), taken as the static
     pull each arm guarantees at its clamp, 9.81 N. *Assumption*: the allowable wrist moments and joint torques
     at the pose (which may allow more where the pull passes near the joint axes) are not in the sources
     available here; the planner's own default, 40 N, is an older unsourced assumption and is shown beside it;
   * **the urethane sheet's strain**: 30 % (:class:`~flexsheet.model.tension.SheetMaterial` ``max_stretch``: the
     range where the neo-Hookean law fits rubber within ~10 %, Treloar 1975; far inside a urethane's elongation
     at break, > 300 %, an assumption for the paper's unnamed grade).

2. **The mapping**: one scale s for the scene, the largest stiffness the sheet can present over the largest the
   scene asks for along its stroke at its stroke depth (``use.stroke_depth``), so that every ratio of two
   stiffnesses, which is what a palpating finger compares, is kept; below the range's floor the sheet presents
   its floor (reported). The smallest stiffness difference a finger notices: a Weber fraction of 23 % (L. A.
   Jones and I. W. Hunter, "A perceptual analysis of stiffness", Exp. Brain Res. 79:150–156, 1990).

3. **What is presented**: along a push at the tumour's place on the stroke and at the median away from it, the
   requested force–depth curve (the scene's stiffness estimate, :class:`flexsheet.planning.compliance.SceneCompliance`,
   integrated over depth, times s) against the presented one (the sheet's stiffness within its range,
   integrated); and the tumour's contrast (its stiffness over the same place without it, less 1) as asked and
   as presented, against the Weber fraction, at each depth.

Writes ``DIR/compliance.json`` and ``DIR/compliance.png``. Units: N, m, N/m in the JSON (mm in the chart).
"""

from __future__ import annotations

import argparse
import json
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np

__all__ = ["ARM_PULL_N", "WEBER", "presentable_range", "run", "main"]

ARM_PULL_N = 1.0 * 9.81        #: the RV-1A's rated payload (1 kg) as the static pull per clamp, N (assumption above)
WEBER = 0.23                   #: Weber fraction for stiffness (Jones & Hunter 1990)
DEPTHS_MM = (0.5, 1.0, 2.0, 3.0, 5.0, 7.5, 10.0)


def presentable_range(arm_pull: float = ARM_PULL_N) -> dict:
    """The sheet's stiffness at its centre (N/m) at the least stretch and at each limit; the presentable range is
    the least stretch up to the first limit reached. Returns stretches, clamp forces and stiffnesses."""
    from flexsheet.model.tension import SheetMaterial, clamp_force, max_stretch_within_force, stiffness

    mat = SheetMaterial()
    rows = {}
    for name, m in (("arm_pull", replace(mat, max_force=arm_pull, max_stretch=10.0)),
                    ("strain", replace(mat, max_force=1e9)),
                    ("planner_default", mat)):
        eps = max_stretch_within_force(m)
        rows[name] = {"stretch": eps, "clamp_force_N": clamp_force(eps, mat), "k_n_per_m": stiffness(eps, mat)}
    eps_max = min(rows["arm_pull"]["stretch"], rows["strain"]["stretch"])
    return {"k_min_n_per_m": stiffness(mat.min_stretch, mat), "min_stretch": mat.min_stretch,
            "k_max_n_per_m": stiffness(eps_max, mat), "max_stretch": eps_max,
            "limited_by": "arm_pull" if rows["arm_pull"]["stretch"] <= rows["strain"]["stretch"] else "strain",
            "limits": rows, "arm_pull_N": arm_pull}


def run(out: Path, scene_file: str, arm_pull: float = ARM_PULL_N) -> dict:
    """Items 1–3 of the module doc for ``scene_file``; writes and returns ``compliance.json``."""
    from flexsheet.experiments.scenes import stiffness_along_path
    from flexsheet.model.scenes import load_scene
    from flexsheet.planning.compliance import SceneCompliance

    sc = load_scene(scene_file)
    rng = presentable_range(arm_pull)
    d_stroke = sc.use.stroke_depth * 1e3
    along = stiffness_along_path(sc, depths_mm=tuple(sorted(set(DEPTHS_MM) | {d_stroke})))
    k_stroke = np.asarray(along["k"][f"{d_stroke:g}"])
    s = rng["k_max_n_per_m"] / float(k_stroke.max())
    arc = np.asarray(along["arc_mm"])
    C = SceneCompliance(sc)
    f = np.linspace(0.0, 1.0, len(arc))
    P, N = sc.stroke_at(f)
    if sc.inclusions:
        i_t = int(np.argmax(k_stroke / np.asarray(along["k_body"][f"{d_stroke:g}"])))
    else:
        i_t = int(np.argmax(k_stroke))
    away = np.abs(arc - arc[i_t]) > 20.0
    i_a = int(np.flatnonzero(away)[np.argsort(k_stroke[away])[len(np.flatnonzero(away)) // 2]]) if away.any() else 0
    depths = np.linspace(0.0005, sc.use.stroke_depth, 40)

    def curve(i: int) -> dict:
        k = np.array([C.estimate(P[i], N[i], d).k for d in depths])
        k_pres = np.clip(s * k, rng["k_min_n_per_m"], rng["k_max_n_per_m"])
        F_req = np.concatenate([[0.0], np.cumsum(0.5 * (k[1:] + k[:-1]) * np.diff(depths))])
        F_pres = np.concatenate([[0.0], np.cumsum(0.5 * (k_pres[1:] + k_pres[:-1]) * np.diff(depths))])
        return {"arc_mm": float(arc[i]), "depth_m": depths.tolist(), "k_requested_n_per_m": k.tolist(),
                "k_presented_n_per_m": k_pres.tolist(), "force_requested_N": F_req.tolist(),
                "force_requested_scaled_N": (s * F_req).tolist(), "force_presented_N": F_pres.tolist(),
                "floor_share": float(np.mean(s * k < rng["k_min_n_per_m"]))}

    push = {"tumour": curve(i_t), "away": curve(i_a)}
    contrast = []
    for d in DEPTHS_MM:
        k = np.asarray(along["k"][f"{d:g}"])
        kb = np.asarray(along["k_body"][f"{d:g}"])
        asked = float(k[i_t] / kb[i_t] - 1.0)
        kp, kpb = (float(np.clip(s * x, rng["k_min_n_per_m"], rng["k_max_n_per_m"])) for x in (k[i_t], kb[i_t]))
        presented = kp / kpb - 1.0
        contrast.append({"depth_mm": d, "asked": asked, "presented": presented,
                         "felt": presented >= WEBER, "tumour_k_presented_n_per_m": kp})
    res = {"title": f"{sc.name}: stiffness presented against requested", "scene": str(scene_file),
           "units": {"stiffness": "N/m", "force": "N", "depth": "m"}, "range": rng,
           "requested_along_stroke": {"depth_mm": d_stroke, "k_min_n_per_m": float(k_stroke.min()),
                                      "k_max_n_per_m": float(k_stroke.max())},
           "scale": s, "weber_fraction": WEBER, "push": push, "tumour_contrast": contrast,
           "verdict": {"tumour_felt_at_depths_mm": [c["depth_mm"] for c in contrast if c["felt"]],
                       "at_stroke_depth": next(c for c in contrast if c["depth_mm"] == d_stroke)["felt"]
                       if d_stroke in DEPTHS_MM else None},
           "sources": {"arm_pull": "RV-1A rated payload 1 kg (Mitsubishi BFP-A8050) as a static pull: assumption",
                       "strain": "neo-Hookean fit range 30 % (Treloar 1975)",
                       "weber": "Jones & Hunter, Exp. Brain Res. 79:150-156 (1990): 23 %"}}
    out.mkdir(parents=True, exist_ok=True)
    (out / "compliance.json").write_text(json.dumps(res, indent=1))
    _chart(res, out / "compliance.png")
    return res


def _chart(res: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rng = res["range"]
    fig, (a1, a2, a3) = plt.subplots(1, 3, figsize=(15, 4.6))
    names = ["least stretch (1 %)", "arm pull 9.81 N", "strain 30 %", "planner default 40 N"]
    vals = [rng["k_min_n_per_m"], rng["limits"]["arm_pull"]["k_n_per_m"], rng["limits"]["strain"]["k_n_per_m"],
            rng["limits"]["planner_default"]["k_n_per_m"]]
    a1.bar(names, vals, color=["tab:gray", "tab:blue", "tab:orange", "tab:gray"])
    req = res["requested_along_stroke"]
    a1.axhspan(req["k_min_n_per_m"], req["k_max_n_per_m"], color="tab:red", alpha=0.15,
               label=f"requested along the stroke at {req['depth_mm']:g} mm")
    a1.set_yscale("log")
    a1.set_ylabel("stiffness at the sheet's centre, N/m (log)")
    a1.set_title(f"presentable: {rng['k_min_n_per_m']:.1f}-{rng['k_max_n_per_m']:.1f} N/m "
                 f"(limited by {rng['limited_by']})", fontsize=9)
    a1.tick_params(axis="x", labelsize=7, rotation=15)
    a1.legend(fontsize=7)
    for key, mk in (("tumour", "-"), ("away", "--")):
        p = res["push"][key]
        d = np.asarray(p["depth_m"]) * 1e3
        a2.plot(d, p["force_requested_scaled_N"], "k" + mk, lw=0.9, label=f"requested × {res['scale']:.3f}, {key}")
        a2.plot(d, p["force_presented_N"], "tab:blue", ls=mk, label=f"presented, {key}")
    a2.set_xlabel("push depth, mm")
    a2.set_ylabel("force, N")
    a2.set_title("force-depth along a push: presented against requested", fontsize=9)
    a2.legend(fontsize=7)
    c = res["tumour_contrast"]
    d = [x["depth_mm"] for x in c]
    a3.plot(d, [100 * x["asked"] for x in c], "o-", label="asked by the scene")
    a3.plot(d, [100 * x["presented"] for x in c], "s--", label="presented")
    a3.axhline(100 * res["weber_fraction"], color="r", ls=":", label="Weber fraction 23 % (target)")
    felt = res["verdict"]["tumour_felt_at_depths_mm"]
    a3.set_title("tumour contrast: " + (f"felt at {felt} mm" if felt else "MISSED: below the Weber fraction at "
                                       "every depth"), fontsize=9)
    a3.set_xlabel("push depth, mm")
    a3.set_ylabel("stiffness over the same place without it, %")
    a3.legend(fontsize=7)
    fig.suptitle(res["title"], fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="flexsheet experiment compliance", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter,
                                 epilog="example: flexsheet experiment compliance --out docs/figures/compliance")
    ap.add_argument("--out", required=True, help="output folder (compliance.json, compliance.png)")
    ap.add_argument("--scene", default="launch/scenes/organ.yaml", help="scene file (default: the organ)")
    ap.add_argument("--arm-pull", type=float, default=ARM_PULL_N, help="static pull per clamp the arms allow, N "
                    "(default %(default)s: the RV-1A's 1 kg payload)")
    a = ap.parse_args(argv)
    if not a.arm_pull > 0:
        ap.error(f"--arm-pull must be > 0 N, got {a.arm_pull}")
    res = run(Path(a.out), a.scene, a.arm_pull)
    r = res["range"]
    print(f"presentable {r['k_min_n_per_m']:.1f}-{r['k_max_n_per_m']:.1f} N/m (limited by {r['limited_by']}); "
          f"scale {res['scale']:.4f}; tumour felt at {res['verdict']['tumour_felt_at_depths_mm']} mm")
    print(f"wrote {a.out}/compliance.json, compliance.png")
    return 0


if __name__ == "__main__":      # pragma: no cover
    sys.exit(main())
