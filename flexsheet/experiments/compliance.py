"""``flexsheet experiment compliance --scene FILE --out DIR``: what the object asks the finger to feel, from
its own FEM, and how it maps into what the sheet can present.

1. **The object's force–depth** (:func:`flexsheet.fem.force_depth.build_force_depth`): the FEM model the node
   serves, pushed along the inward normal at points along the stroke (the first, its start, is ``reference``:
   the sphere's crown). Checked against Hertz's closed form at 1–3 mm where it applies (a smooth convex body
   without inclusions: the cylinder and the sphere). Written to ``DIR/force_depth.json``.
2. **The presentable range** at the sheet's centre: the sheet model's force (``--sheet``: a ``sheet.json``
   from ``flexsheet calibrate sheet``; default the nominal string band) at its least stretch and at the
   largest the arms allow at the home pose (``pull_margin`` 0.9 × the torque-limited pull,
   :mod:`flexsheet.arm.pull_limit`, and the 30 % strain).
3. **The mapping** (:func:`flexsheet.model.force_depth.scene_scale`): one scale per scene, the geometric
   centre of the scales that keep every point's force over 2 mm to twice the stroke depth inside the range;
   every ratio of two forces is kept. With ``--contrast-gain`` γ > 1 the request is s·F_ref·(F/F_ref)^γ.
4. **Contrast**: per point, its force over the median point's at the same depth, less 1, as asked and as
   presented (mapped and clipped to the range), against the Weber fraction (15 %, Bergmann Tiest & Kappers
   2009).

Writes ``DIR/force_depth.json``, ``DIR/compliance.json`` and ``DIR/compliance.png``. Units: N, m in the JSON
(mm in the chart).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

from flexsheet.calibration.sheet import OPTIONAL_TERMS, TERMS, with_terms
from flexsheet.fem.force_depth import build_force_depth, hertz_check
from flexsheet.fem.served import served_model
from flexsheet.model import geometry
from flexsheet.model.scenes import load_scene
from flexsheet.model.sheet import clamp_poses
from flexsheet.model.tension import SheetMaterial, clamp_force, max_stretch_within_force, press_force
from flexsheet.planning.pull_guard import PullGuard
from flexsheet.planning.scene_scale import scale_depths, sheet_scene_scale

__all__ = ["WEBER", "presentable_range", "run", "main"]

#: Weber fraction for force/stiffness with the surface cue (Bergmann Tiest & Kappers 2009)
WEBER = 0.15


def presentable_range(sheet_file: str | None = None) -> dict:
    """The sheet at its centre: ``material`` (the model used), ``min_stretch``, ``max_stretch`` (the first of
    the pull guard's margin (0.9, :class:`flexsheet.planning.pull_guard.PullGuard`) × the arms' torque-limited
    pull at the home pose and the strain limit), ``pull_n`` (that pull, N), ``limited_by`` ("arm_torque" or
    "strain"), ``source``. Raises ``ValueError`` for an unreadable ``sheet_file``."""
    from dataclasses import replace

    mat = SheetMaterial()
    source = "nominal string band (no identified sheet)"
    if sheet_file:
        try:
            fit = json.loads(Path(sheet_file).read_text())["fit"]
            mat = with_terms(type("Fit", (),
                                  {k: fit.get(k, 0.0) if k in OPTIONAL_TERMS else fit[k] for k in TERMS})(),
                             mat)
        except (OSError, KeyError, ValueError, TypeError) as exc:
            raise ValueError(f"--sheet {sheet_file}: not a sheet.json of flexsheet calibrate sheet "
                             f"({exc})") from None
        source = f"identified ({sheet_file})"
    guard = PullGuard({"left": geometry.LEFT_BASE, "right": geometry.RIGHT_BASE})
    Tl, Tr = clamp_poses(np.zeros(3), np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0]), mat.min_stretch,
                         mat.size)
    pull = guard.limit(Tl, Tr)
    capped = replace(mat, max_force=min(mat.max_force, pull)) if pull is not None else mat
    e_max = max_stretch_within_force(capped)
    strain_first = e_max >= mat.max_stretch - 1e-12
    return {"material": {k: getattr(mat, k) for k in TERMS}, "min_stretch": mat.min_stretch,
            "max_stretch": e_max,
            "pull_n": pull, "clamp_force_at_max_n": clamp_force(e_max, mat),
            "limited_by": "strain" if strain_first else "arm_torque", "source": source,
            "_mat": mat}


def run(out: Path, scene_file: str, sheet_file: str | None = None, gain: float = 1.0) -> dict:
    """Items 1–4 of the module doc; writes and returns ``compliance.json`` (and ``force_depth.json``)."""
    sc = load_scene(scene_file)
    rng = presentable_range(sheet_file)          # a bad --sheet fails before the FEM is built
    mat = rng.pop("_mat")
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    model, what = served_model(sc)
    table = build_force_depth(sc, model)
    build_s = time.perf_counter() - t0
    hz = hertz_check(sc, table)
    fd = {"title": f"{sc.name}: force-depth along the stroke, from the served FEM", "scene": str(scene_file),
          "model": what, "build_s": build_s, "units": {"position": "m", "depth": "m", "force": "N"},
          **table.to_json(), "hertz_check": hz,
          "verdict": ("no closed form applies (inclusions or not a cylinder or sphere)" if hz is None else
                      ("met" if all(abs(r - 1.0) <= 0.15 for r in hz["ratio"]) else "MISSED")
                      + ": within 15 % of Hertz at 1-3 mm")}
    (out / "force_depth.json").write_text(json.dumps(fd, indent=1))
    e_lo, e_hi = rng["min_stretch"], rng["max_stretch"]
    d_lo, d_hi = scale_depths(sc.use.stroke_depth)
    floor = lambda d: press_force(e_lo, mat, 0.0, d)        # noqa: E731
    ceil = lambda d: press_force(e_hi, mat, 0.0, d)         # noqa: E731
    ss = sheet_scene_scale(table, mat, e_hi, sc.use.stroke_depth, gain)
    depths = [d for d in table.depths if d_lo - 1e-12 <= d <= d_hi + 1e-12]
    points = []
    for name, p in zip(table.names, table.points, strict=True):
        asked = [table.force_at(p, d) / table.reference_force(d) - 1.0 for d in depths]
        req = [table.mapped(p, d, ss.scale, gain)[0] for d in depths]
        pres = [float(np.clip(r, floor(d), ceil(d))) for r, d in zip(req, depths, strict=True)]
        ref_pres = [float(np.clip(ss.scale * table.reference_force(d), floor(d), ceil(d))) for d in depths]
        presented = [a / b - 1.0 if b > 0 else 0.0 for a, b in zip(pres, ref_pres, strict=True)]
        points.append({"name": name, "position_m": p.tolist(),
                       "force_n": [table.force_at(p, d) for d in depths],
                       "requested_n": req, "presented_n": pres, "contrast_asked": asked,
                       "contrast_presented": presented})
    best = max(points, key=lambda x: float(np.median(x["contrast_asked"])))
    res = {"title": f"{sc.name}: force presented against requested", "scene": str(scene_file),
           "units": {"force": "N", "depth": "m"}, "depth_m": depths, "range": rng,
           "floor_n": [floor(d) for d in depths], "ceiling_n": [ceil(d) for d in depths],
           "scale": ss.scale, "scale_low": ss.low, "scale_high": ss.high, "fits": ss.fits,
           "saturated": ss.saturated, "contrast_gain": gain, "weber_fraction": WEBER, "points": points,
           "stiffest_point": {"name": best["name"],
                              "contrast_asked_median": float(np.median(best["contrast_asked"])),
                              "contrast_presented_median": float(np.median(best["contrast_presented"]))},
           "target": "saturated <= 0.05 of the scene's samples; contrast above the Weber fraction is felt",
           "verdict": "met" if ss.saturated <= 0.05 else "MISSED",
           "sources": {"force": "the served FEM (flexsheet/fem/served.py), pushed along the normal",
                       "pull": "flexsheet/arm/pull_limit.py (torque limits: assumptions, flagged there)",
                       "weber": "Bergmann Tiest & Kappers, IEEE Trans. Haptics 2:189 (2009): 15 %"}}
    (out / "compliance.json").write_text(json.dumps(res, indent=1))
    _chart(res, fd, out / "compliance.png")
    return res


def _chart(res: dict, fd: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (a1, a2, a3) = plt.subplots(1, 3, figsize=(15, 4.6))
    D = np.asarray(fd["points"][0]["depth_m"]) * 1e3
    for p in fd["points"]:
        a1.plot(D, p["force_n"], lw=0.6, color="tab:blue" if p["name"] != "reference" else "k")
    h = fd.get("hertz_check")
    if h:
        a1.plot(np.asarray(h["depth_m"]) * 1e3, h["hertz_n"], "r^", label="Hertz (Johnson 1985)")
        a1.legend(fontsize=7)
    a1.set_xlim(0, min(D[-1], 4 * res["depth_m"][-1] * 1e3))
    a1.set_xlabel("push depth, mm")
    a1.set_ylabel("object's force, N")
    hz = "Hertz at 1-3 mm: " + fd["verdict"].split(":")[0] if h else "no closed form applies"
    a1.set_title(f"object's FEM force-depth, {len(fd['points'])} points ({hz})", fontsize=8)
    d = np.asarray(res["depth_m"]) * 1e3
    a2.fill_between(d, res["floor_n"], res["ceiling_n"], color="tab:green", alpha=0.15,
                    label=f"presentable ({res['range']['limited_by']})")
    for p in res["points"]:
        a2.plot(d, p["requested_n"], lw=0.6, color="tab:blue")
    a2.set_xlabel("push depth, mm")
    a2.set_ylabel("force asked of the sheet, N")
    a2.set_title(f"scale {res['scale']:.3g} (fits {res['scale_low']:.3g}-{res['scale_high']:.3g}); saturated "
                 f"{100 * res['saturated']:.1f} % (<= 5 %): {res['verdict']}", fontsize=8)
    a2.legend(fontsize=7)
    b = next(p for p in res["points"] if p["name"] == res["stiffest_point"]["name"])
    a3.plot(d, 100 * np.asarray(b["contrast_asked"]), "o-", label="asked by the object")
    a3.plot(d, 100 * np.asarray(b["contrast_presented"]), "s--",
            label=f"presented (contrast_gain {res['contrast_gain']:g})")
    a3.axhline(100 * res["weber_fraction"], color="r", ls=":", label="Weber fraction 15 %")
    a3.set_xlabel("push depth, mm")
    a3.set_ylabel("force over the median point's, %")
    a3.set_title(f"contrast at the stiffest point ({b['name']})", fontsize=8)
    a3.legend(fontsize=7)
    fig.suptitle(res["title"], fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="flexsheet experiment compliance", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter,
                                 epilog="example: flexsheet experiment compliance --scene "
                                        "launch/scenes/organ.yaml --sheet "
                                        "docs/figures/calibration/sheet/sheet.json --out "
                                        "docs/figures/compliance")
    ap.add_argument("--out", required=True, help="output folder (force_depth.json, compliance.json, "
                                                 "compliance.png)")
    ap.add_argument("--scene", default="launch/scenes/organ.yaml", help="scene file (default: the organ)")
    ap.add_argument("--sheet", default=None, help="sheet.json of `flexsheet calibrate sheet` (default: the "
                    "nominal string band)")
    ap.add_argument("--contrast-gain", type=float, default=1.0, help="γ of the mapping (default 1: faithful)")
    a = ap.parse_args(argv)
    if not 0.0 < a.contrast_gain <= 5.0:
        ap.error(f"--contrast-gain must be in (0, 5], got {a.contrast_gain}")
    try:
        res = run(Path(a.out), a.scene, a.sheet, a.contrast_gain)
    except (ValueError, FileNotFoundError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    sp = res["stiffest_point"]
    print(f"scale {res['scale']:.4g} (fits {res['scale_low']:.4g}-{res['scale_high']:.4g}); saturated "
          f"{100 * res['saturated']:.1f} %: {res['verdict']}; stiffest point {sp['name']}: contrast asked "
          f"{100 * sp['contrast_asked_median']:.1f} %, presented {100 * sp['contrast_presented_median']:.1f} "
          "%")
    print(f"wrote {a.out}/force_depth.json, compliance.json, compliance.png")
    return 0


if __name__ == "__main__":      # pragma: no cover
    sys.exit(main())
