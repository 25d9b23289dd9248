"""``flexsheet experiment scenes``: the display on every shipped scene, in-process — Table I per
scene and the organ's compliance along its stroke (the tumour's stiffness peak in the sheet's tension).

1. **Table I per scene** (``launch/scenes/{cylinder,sphere,rounded_box,organ}.yaml``): the in-process stroke
   of :func:`flexsheet.experiments.stroke_model.simulate` (honest twin, camera noise, Kalman prediction,
   latency, the arms' IK / command stream / servo / true kinematics) with the scripted finger on the scene's
   stroke path, the planner on the scene's shape with the tension from the scene's compliance estimate
   (:class:`flexsheet.planning.compliance.SceneCompliance`, what the planner node does while the FEM does not
   solve the scene), and the metric in the normal section along the scene's stroke
   (:func:`flexsheet.analysis.table1.scene_table1_row`). Realistic twin, truth seeds 0…``seeds``−1, moving
   times 10 s and 30 s. Each row also has the tension the planner set at the contacts (median, p5, p95, N/m;
   truth seed 0's run), the requested object stiffness and the share of samples at the arms' limit.
2. **The organ's compliance** (``organ.yaml``, a stiff 14 mm tumour 8.6 mm under the stroke):
   a. the estimate along the path at fixed push depths 0.5, 2, 5 and 10 mm, with and without the inclusion;
   b. the scripted runs — the light stroke (0.5 mm, 10 s) and the world's stroke-and-push (10 s, pushed to
      10 mm on a half sine) — through the planner: the requested stiffness, the stiffness the sheet presents
      and the tension, against the contact's place on the path; the stroke-and-push once with the object's
      own stiffness (``stiffness_scale`` 1: it saturates at the arms' limit) and once with the haptic scale
      that fits the run into the arms' range (reported).

Outputs in ``--out DIR`` (default docs/figures/scenes): ``summary.json`` (``table1``: scene → rows,
``organ``: the peak figures), ``table1_scenes.json``, ``compliance_organ.json`` (every number of the chart),
``compliance_organ.png`` (Agg).
"""

from __future__ import annotations

import argparse
import json
import logging
import math
import sys
import time
from pathlib import Path

import numpy as np

from flexsheet.experiments.stroke_model import LatencyModel, launch_kf, make_twin, simulate
from flexsheet.model.scenes import SCENES_DIR, load_scene
from flexsheet.model.tension import SheetMaterial, max_stretch_within_force, stiffness, stretch_for_stiffness
from flexsheet.planning.compliance import SceneCompliance
from flexsheet.planning.planner_config import PlannerConfig

log = logging.getLogger(__name__)

__all__ = ["SCENE_NAMES", "table1_for_scene", "stiffness_along_path", "organ_runs", "run", "main"]

SCENE_NAMES = ("cylinder", "sphere", "rounded_box", "organ")
DEPTHS_MM = (0.5, 2.0, 5.0, 10.0)
#: the palpation run's push depth while stroking, m
PALPATION_DEPTH = 0.005
DEFAULT_OUT = Path("out") / "scenes"


def _rounded(x, digits: int = 5):
    """``x`` (nested dicts/lists) with every float rounded to ``digits`` significant digits (for the JSON)."""
    if isinstance(x, float):
        return float(f"{x:.{digits}g}") if math.isfinite(x) else x
    if isinstance(x, dict):
        return {k: _rounded(v, digits) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_rounded(v, digits) for v in x]
    return x


def _pct(x) -> dict:
    x = np.asarray(x, float)
    return {"median": float(np.median(x)), "p5": float(np.percentile(x, 5)),
            "p95": float(np.percentile(x, 95))}


def _compliance_stats(record: list, t0: float, t1: float) -> dict:
    plans = [p for t, _, p in record if t0 <= t < t1 and not p.status.startswith("hold")]
    return {"tension_n_per_m": _pct([p.tension for p in plans]),
            "object_stiffness_n_per_m": _pct([p.object_stiffness for p in plans]),
            "stiffness_n_per_m": _pct([p.stiffness for p in plans]),
            "at_limit": float(np.mean([("stiffer_than_sheet" in p.status) or ("softer_than_sheet" in p.status)
                                       for p in plans]))}


def table1_for_scene(name: str, seeds: int = 3, times=(10.0, 30.0)) -> dict:
    """Table I rows of scene ``name`` (module doc, item 1): ``{"10": mean row with ``per_seed``, …}``."""
    sc = load_scene(SCENES_DIR / f"{name}.yaml")
    lk = launch_kf()
    out: dict = {}
    for T in times:
        rows = []
        for s in range(seeds):
            t_start = time.monotonic()
            tw = make_twin("realistic", s, None)
            rec: list = []
            st: dict = {}
            row = simulate(T, tw, LatencyModel(), s, use_prediction=bool(lk["use_prediction"]), scene=sc,
                           compliance=SceneCompliance(sc), stats=st, record=rec)
            t_move = 2.0            # approach 1 s + hold 1 s (FingerScript defaults)
            row.update({k: float(v) for k, v in st.items()})
            row.update(_compliance_stats(rec, t_move, t_move + T))
            rows.append(row)
            log.info(f"  {name:<12} {T:>4g} s seed {s}: dθ {row['dtheta_mean_deg']:.3f}° Δd "
                f"{row['dd_mean_mm']:.3f} mm, tension {row['tension_n_per_m']['median']:.0f} N/m, IK refused "
                f"{st['ik_refused']} ({time.monotonic() - t_start:.1f} s)")
        keys = [k for k, v in rows[0].items() if isinstance(v, float)]
        mean = {k: float(np.mean([r[k] for r in rows])) for k in keys}
        mean["n"] = int(sum(r["n"] for r in rows))
        mean["seeds"] = len(rows)
        for k in ("tension_n_per_m", "object_stiffness_n_per_m", "stiffness_n_per_m"):
            mean[k] = rows[0][k]                   # percentiles of truth seed 0's run
        mean["compliance_of_truth_seed"] = 0
        mean["per_seed"] = [{"truth_seed": i, "dtheta_mean_deg": r["dtheta_mean_deg"],
                             "dd_mean_mm": r["dd_mean_mm"],
                             "ik_refused": r["ik_refused"]} for i, r in enumerate(rows)]
        out[f"{T:g}"] = mean
    return out


def _path_arc(scene, points: np.ndarray, n: int = 1025) -> np.ndarray:
    """Arc length (N,) m along ``scene``'s stroke of the path point nearest each of ``points`` (N, 3) m."""
    P, _ = scene.stroke_points(n)
    L = scene.stroke_length()
    d2 = ((points[:, None, :] - P[None, :, :]) ** 2).sum(-1)
    return np.argmin(d2, axis=1) * (L / (n - 1))


def stiffness_along_path(scene, depths_mm=DEPTHS_MM, n: int = 121) -> dict:
    """The compliance estimate along ``scene``'s stroke (``n`` points) at each push depth in ``depths_mm``:
    ``{"arc_mm", "k": {depth: (n,) N/m}, "k_body": {depth: (n,)}, "E_eff_kpa": {depth: (n,)},
    "inclusions": [{"name", "arc_mm" of the nearest path point, "distance_mm" centre to path surface}]}``."""
    C = SceneCompliance(scene)
    f = np.linspace(0.0, 1.0, n)
    P, N = scene.stroke_at(f)
    L = scene.stroke_length()
    out: dict = {"arc_mm": (f * L * 1e3).tolist(), "k": {}, "k_body": {}, "E_eff_kpa": {}}
    for d in depths_mm:
        est = [C.estimate(p, q, d * 1e-3) for p, q in zip(P, N, strict=True)]
        out["k"][f"{d:g}"] = [e.k for e in est]
        out["k_body"][f"{d:g}"] = [e.k_body for e in est]
        out["E_eff_kpa"][f"{d:g}"] = [e.E_eff * 1e-3 for e in est]
    incs = []
    for inc in scene.inclusions:
        c = np.asarray(inc.center, float)
        i = int(np.argmin(np.linalg.norm(P - c, axis=1)))
        incs.append({"name": inc.name, "arc_mm": float(f[i] * L * 1e3),
                     "distance_mm": float(np.linalg.norm(P[i] - c) * 1e3), "radius_mm": inc.radius * 1e3,
                     "E_kpa": inc.E * 1e-3})
    out["inclusions"] = incs
    return out


def run_series(scene, mode: str, scale: float, seed: int = 0, depth: float = 5e-4,
               push_depth: float | None = None,
               moving_time: float = 10.0) -> tuple[dict, dict]:
    """One scripted run through the planner (realistic twin ``seed``; ``mode`` as the world's segments, finger
    ``depth`` m while stroking, ``push_depth`` m for stroke_push, default the scene's ``use.stroke_depth``):
    per sample during the moving phase the contact's arc (mm), the planned depth (mm), the object's stiffness
    (the planner's request / ``scale``), the requested and presented stiffness and the tension (N/m), the
    status at the limit, the tumour's ``contrast`` (the estimate at the contact and depth over the same
    without the inclusions) and the tension the same request without the tumour would need at the same place
    on the sheet."""
    push_depth = scene.use.stroke_depth if push_depth is None else push_depth
    tw = make_twin("realistic", seed, None)
    rec: list = []
    kw = {"mode": mode, "depth": depth}
    if mode != "stroke":
        kw["push_depth"] = push_depth
    row = simulate(moving_time, tw, LatencyModel(), seed + (2 if mode == "stroke_push" else 0),
                   use_prediction=bool(launch_kf()["use_prediction"]), scene=scene,
                   compliance=SceneCompliance(scene), planner_config=PlannerConfig(stiffness_scale=scale),
                   record=rec, finger_kw=kw)
    t_move = 2.0
    sel = [(t, p) for t, _, p in rec if t_move <= t < t_move + moving_time]
    q = np.array([p.contact for _, p in sel])
    C = SceneCompliance(scene)
    est = [C.estimate(p.contact, p.normal, p.depth) for _, p in sel]
    mat = PlannerConfig().material
    emax = max_stretch_within_force(mat)
    series = {"t_s": [t for t, _ in sel], "arc_mm": (_path_arc(scene, q) * 1e3).tolist(),
              "depth_mm": [p.depth * 1e3 for _, p in sel],
              "requested_n_per_m": [p.object_stiffness for _, p in sel],
              "object_n_per_m": [p.object_stiffness / scale for _, p in sel],
              "presented_n_per_m": [p.stiffness for _, p in sel],
              "tension_n_per_m": [p.tension for _, p in sel],
              "at_limit": [("stiffer_than_sheet" in p.status) or ("softer_than_sheet" in p.status) for _,
                           p in sel],
              "contrast": [e.k / e.k_body for e in est],
              "tension_without_tumour_n_per_m": [
                  stretch_for_stiffness(p.object_stiffness * e.k_body / e.k, mat, p.offset[0], emax, 0.0,
                                        p.offset[1]).tension
                  for (_, p), e in zip(sel, est, strict=True)],
              "stiffness_scale": scale, "finger_depth_mm": depth * 1e3,
              "push_depth_mm": push_depth * 1e3 if mode != "stroke" else None,
              "table1": {k: row[k] for k in ("dtheta_mean_deg", "dd_mean_mm", "n")}}
    return series, row


def _binned(arc, y, edges) -> np.ndarray:
    arc, y = np.asarray(arc), np.asarray(y)
    idx = np.digitize(arc, edges) - 1
    return np.array([np.median(y[idx == i]) if np.any(idx == i) else np.nan for i in range(len(edges) - 1)])


def peak_along_path(series: dict, arc_inc: float, bin_mm: float = 4.0) -> dict:
    """Where a run's requested stiffness, presented stiffness and tension peak along the path (medians in
    ``bin_mm`` bins of the contact's arc): the bin centre of each maximum, mm, the tumour's arc, and the
    presented stiffness there over the median of the bins farther than 15 mm from it."""
    arc = np.asarray(series["arc_mm"])
    edges = np.arange(0.0, arc.max() + bin_mm, bin_mm)
    mid = 0.5 * (edges[1:] + edges[:-1])
    out: dict = {"tumour_arc_mm": arc_inc}
    tension_ratio = np.asarray(series["tension_n_per_m"]) / np.asarray(
        series["tension_without_tumour_n_per_m"])
    for key in ("object_n_per_m", "presented_n_per_m", "tension_n_per_m", "contrast",
                "tension_over_no_tumour"):
        b = _binned(arc, tension_ratio if key == "tension_over_no_tumour" else series[key], edges)
        i = int(np.nanargmax(b))
        far = np.abs(mid - arc_inc) > 15.0
        out[key] = {"arc_of_max_mm": float(mid[i]), "max": float(b[i]),
                    "max_over_far_median": float(b[i] / np.nanmedian(b[far])) if far.any() else None}
    return out


def organ_runs(quick: bool = False) -> dict:
    """Module doc, item 2: the organ's stiffness along the path and the scripted runs."""
    sc = load_scene(SCENES_DIR / "organ.yaml")
    along = stiffness_along_path(sc)
    arc_inc = along["inclusions"][0]["arc_mm"]
    k = {d: np.asarray(v) for d, v in along["k"].items()}
    kb = {d: np.asarray(v) for d, v in along["k_body"].items()}
    arc = np.asarray(along["arc_mm"])
    peaks = {d: {"arc_of_max_mm": float(arc[np.argmax(k[d])]), "contrast_max": float(np.max(k[d] / kb[d])),
                 "arc_of_contrast_max_mm": float(arc[np.argmax(k[d] / kb[d])]),
                 "k_max_n_per_m": float(np.max(k[d])), "k_min_n_per_m": float(np.min(k[d]))} for d in k}
    mat = SheetMaterial()
    k_sheet = {"min_n_per_m": stiffness(mat.min_stretch, mat),
               "max_n_per_m": stiffness(max_stretch_within_force(mat), mat),
               "note": "the sheet's normal stiffness at its centre between the stretch limits (tension.py)"}
    palp1, _ = run_series(sc, "stroke", 1.0, depth=PALPATION_DEPTH)
    scale = round(0.9 * k_sheet["max_n_per_m"] / float(np.percentile(palp1["object_n_per_m"], 99)), 3)
    palp, _ = run_series(sc, "stroke", scale, depth=PALPATION_DEPTH)
    runs = {"palpation": palp, "palpation_unscaled": palp1}
    if not quick:
        runs["light_stroke"], _ = run_series(sc, "stroke", 1.0)
        runs["stroke_push"], _ = run_series(sc, "stroke_push", 1.0)
    return {"scene": str(SCENES_DIR / "organ.yaml"), "along_path": along, "peaks_along_path": peaks,
            "sheet_range": k_sheet, "runs": runs, "fitted_scale": scale,
            "run_peaks": {k: peak_along_path(v, arc_inc) for k, v in runs.items()}}


def _plot(org: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(3, 1, figsize=(9, 11.5))
    al = org["along_path"]
    arc_inc = al["inclusions"][0]["arc_mm"]
    for d in al["k"]:
        line, = ax[0].plot(al["arc_mm"], al["k"][d], label=f"{d} mm push")
        ax[0].plot(al["arc_mm"], al["k_body"][d], ls=":", color=line.get_color(), lw=0.9)
    ax[0].set(ylabel="object stiffness dF/dd [N/m]", yscale="log",
              title="organ: the scene's stiffness estimate along the stroke (dotted: without the tumour)")
    rng = org["sheet_range"]
    for a in ax:
        a.axvline(arc_inc, color="r", lw=1.0, ls="--", label="tumour (nearest path point)")
        a.grid(True, alpha=0.3)
    ax[0].axhspan(rng["min_n_per_m"], rng["max_n_per_m"], color="g", alpha=0.08,
                  label="what the sheet can present (centre)")
    ax[0].legend(fontsize=7, loc="upper left")
    r = org["runs"]["palpation"]
    s = r["stiffness_scale"]
    a = ax[1]
    a.plot(r["arc_mm"], r["requested_n_per_m"], ".", ms=3, color="k",
           label=f"requested: object stiffness x {s:g}")
    a.plot(r["arc_mm"], r["presented_n_per_m"], ".", ms=3, color="C0", label="sheet stiffness presented")
    a2 = a.twinx()
    a2.plot(r["arc_mm"], r["tension_n_per_m"], ".", ms=3, color="C1", label="sheet tension (right axis)")
    a2.plot(r["arc_mm"], r["tension_without_tumour_n_per_m"], ".", ms=1.5, color="C1", alpha=0.35,
            label="tension without the tumour (same place on the sheet)")
    a.set(ylabel="stiffness [N/m]", title=f"organ, stroking pressed {r['finger_depth_mm']:g} mm (palpation), "
          f"10 s, stiffness_scale {s:g}: planner in-process, realistic twin\n(the tension falls along the "
          "path as the sheet rolls: the contact nears a clamp, where less tension gives the same "
          "stiffness)", )
    a.title.set_fontsize(9)
    a2.set_ylabel("tension [N/m]")
    h1, l1 = a.get_legend_handles_labels()
    h2, l2 = a2.get_legend_handles_labels()
    a.legend(h1 + h2, l1 + l2, fontsize=7, loc="lower left")
    styles = {"palpation": ("C0", f"pressed {r['finger_depth_mm']:g} mm"),
              "light_stroke": ("C2", "light stroke 0.5 mm"),
              "stroke_push": ("C3", "stroke and push (half sine to 10 mm)")}
    for key, (c, lbl) in styles.items():
        if key in org["runs"]:
            rr = org["runs"][key]
            ax[2].plot(rr["arc_mm"], rr["contrast"], ".", ms=3, color=c, label=lbl)
    ax[2].set(xlabel="contact position along the stroke [mm]",
              ylabel="stiffness / stiffness without the tumour",
              title="the tumour's share of the stiffness along each run (same contact and depth)")
    ax[2].legend(fontsize=7, loc="upper left")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def run(out: Path, seeds: int = 3, quick: bool = False, scenes=SCENE_NAMES) -> dict:
    """Both parts (module doc); writes the files under ``out`` and returns the summary."""
    times = (10.0,) if quick else (10.0, 30.0)
    n_seeds = 1 if quick else seeds
    table = {}
    for name in scenes:
        log.info(f"[scenes] Table I on {name} ({n_seeds} seed(s), {', '.join(f'{t:g} s' for t in times)})")
        table[name] = table1_for_scene(name, n_seeds, times)
    summary: dict = {"table1": table, "twin": "realistic", "truth_seeds": list(range(n_seeds)),
                     "note": "planner tension from the scene's compliance estimate (no FEM); metric in the "
                             "normal section along each scene's stroke (for the cylinder: Fig. 9's "
                             "cross-section)"}
    out.mkdir(parents=True, exist_ok=True)
    (out / "table1_scenes.json").write_text(json.dumps(_rounded(table), indent=1))
    if "organ" in scenes:
        log.info("[scenes] organ compliance along the stroke")
        org = organ_runs(quick)
        (out / "compliance_organ.json").write_text(json.dumps(_rounded(org)))
        _plot(org, out / "compliance_organ.png")
        summary["organ"] = {"peaks_along_path": org["peaks_along_path"],
                            "inclusion": org["along_path"]["inclusions"],
                            "run_peaks": org["run_peaks"], "fitted_scale": org["fitted_scale"],
                            "sheet_range": org["sheet_range"]}
    (out / "summary.json").write_text(json.dumps(_rounded(summary), indent=1))
    return summary


def main(argv: list[str] | None = None) -> int:
    """CLI entry: ``flexsheet experiment scenes [--out DIR] [--seeds N] [--quick] [--scene NAME …]``."""
    ap = argparse.ArgumentParser(
        prog="flexsheet experiment scenes", description=__doc__.split("\n")[0],
        epilog="example: flexsheet experiment scenes --out docs/figures/scenes\n"
               "         flexsheet experiment scenes --out /tmp/sc --quick --scene organ",
        formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", type=Path, default=DEFAULT_OUT, help=f"output folder (default {DEFAULT_OUT})")
    ap.add_argument("--seeds", type=int, default=3, help="truth seeds per scene and moving time (default 3)")
    ap.add_argument("--quick", action="store_true", help="one seed, 10 s only")
    ap.add_argument("--scene", action="append", choices=SCENE_NAMES, help="only these scenes (repeatable)")
    a = ap.parse_args(argv)
    if a.seeds < 1:
        ap.error(f"--seeds must be >= 1, got {a.seeds}")
    s = run(a.out, a.seeds, a.quick, tuple(a.scene) if a.scene else SCENE_NAMES)
    print(f"{'scene':<12}{'T s':>5}{'Δθ mean deg':>13}{'Δθ std':>9}{'Δd mm':>9}{'tension N/m':>13}"
          f"{'k_obj N/m':>11}{'at limit':>9}{'IK refused':>11}")
    for name, rows in s["table1"].items():
        for k, r in rows.items():
            print(f"{name:<12}{k:>5}{r['dtheta_mean_deg']:13.3f}{r['dtheta_std_deg']:9.3f}{r['dd_mean_mm']:9.3f}"
                  f"{r['tension_n_per_m']['median']:13.1f}{r['object_stiffness_n_per_m']['median']:11.1f}"
                  f"{r['at_limit']:9.0%}{r['ik_refused']:11.0f}")
    if "organ" in s:
        for d, p in s["organ"]["peaks_along_path"].items():
            print(f"organ {d} mm: stiffness max {p['k_max_n_per_m']:.1f} N/m at {p['arc_of_max_mm']:.1f} mm, "
                  f"tumour contrast x{p['contrast_max']:.3f} at {p['arc_of_contrast_max_mm']:.1f} mm "
                  f"(tumour at {s['organ']['inclusion'][0]['arc_mm']:.1f} mm)")
    print(f"[scenes] wrote {a.out}/summary.json, table1_scenes.json"
          + (", compliance_organ.json/png" if "organ" in s else ""))
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())

