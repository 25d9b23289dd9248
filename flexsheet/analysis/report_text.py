"""The text of a run report (:mod:`flexsheet.analysis.report`): plain text for the terminal
(:func:`format_text`) and ``report.md`` (:func:`markdown`), both from one list of sections
(:func:`sections`). Tables are fixed-width: columns two or more spaces apart, the row key first."""

from __future__ import annotations

import math

from flexsheet.analysis.report_timing import POSE_TOL_M
from flexsheet.analysis.report_verdicts import HEADLINE_METRIC, NO_TARGET, PARTIAL, digits, row_order
from flexsheet.analysis.table1 import DD_CONVENTION, FELT_TARGET_FACTOR, PAPER_TABLE1, TARGET_FACTOR

__all__ = ["sections", "format_text", "markdown", "CHARTS"]

#: the charts report.md shows (file, caption)
CHARTS = (("table1.png", "Table I headline: felt Δθ per segment"), ("felt.png", "felt Δθ over each segment"),
          ("latency.png", "latency per hop"),
          ("compliance.png", "force felt against force requested"),
          ("head.png", "the viewer's head: view error and keep-out distance"),
          ("graph.png", "node/topic graph"))

_TARGETS_AT = "flexsheet/analysis/table1.py"


def _table(header: list[str], rows: list[list[str]]) -> list[str]:
    """Fixed-width lines, columns two spaces apart: numeric columns right-aligned, the others (and the first,
    the row key) left-aligned."""
    cols = [header, *rows]
    w = [max(len(r[i]) for r in cols) for i in range(len(header))]
    right = [i > 0 and all(r[i][:1] in "0123456789-+≤" for r in rows) for i in range(len(header))]
    return ["  ".join(c.rjust(w[i]) if right[i] else c.ljust(w[i]) for i, c in enumerate(r)).rstrip()
            for r in cols]


def _num(v: float | None, d: int = 3) -> str:
    return "-" if v is None else f"{v:.{d}f}"


def _label(key: str) -> str:
    return f"{key} s"


def _header(s: dict) -> list[str]:
    run, sc, tw = s.get("run", {}), s.get("scene", {}), s.get("twin", {})
    lines = []
    if run:
        lines.append(("Run: PARTIAL — " if run.get("partial") else "Run: complete — ") + run.get("note", "")
                     + (": partial rows and the run get no verdict" if run.get("partial") else ""))
    lines.append(f"scene: {sc.get('name', 'cylinder')} "
                 f"({sc.get('file') or sc.get('source', 'the paper cylinder')})")
    lines.append(f"twin: {tw.get('realism', '?')}, truth seed {tw.get('truth_seed', '?')} "
                 f"({tw.get('source', '?')})")
    ck = s.get("clock") if isinstance(s.get("clock"), dict) else {"kind": s.get("clock")}
    clock = ck.get("kind")
    if clock == "sim":
        rtf, target = s.get("realtime_factor"), ck.get("rtf_target")
        lines.append("clock: sim (simulated): every latency is modelled from the lab's declared timings"
                     + (f"; real-time factor {rtf:.2f}" if isinstance(rtf, (int, float)) else "")
                     + (f" (paced at {target:g})" if isinstance(target, (int, float)) else " (unpaced)"))
    elif clock == "wall":
        lines.append("clock: wall: latencies are measured on this host (the projector's is modelled)")
    hl = s.get("headline")
    if hl:
        lines.append(f"Headline verdict (felt Δθ, Table I): {hl['overall']}")
    return lines


def _headline(s: dict) -> tuple[list[str], list[str]]:
    hl = s.get("headline") or {}
    prose = [f"One headline per stroking segment, the felt Δθ mean. {HEADLINE_METRIC[0].upper()}"
             f"{HEADLINE_METRIC[1:]}.",
             f"Target: paper Table I ÷ {FELT_TARGET_FACTOR:g} (FELT_TARGET_FACTOR in {_TARGETS_AT}), for the "
             "paper's rows on the paper's cylinder only. Verdicts compare the unrounded mean with the "
             "unrounded target (met: mean ≤ target); where both round alike, more digits are printed."]
    rows = []
    for k, r in hl.get("rows", {}).items():
        tgt = r["target_deg"]
        d = digits(r["dtheta_mean_deg"], tgt)
        m = r["margin_pct"]
        n = f"{r['n']}" + (f" of {r['expected_n']}" if r.get("expected_n") else "")
        rows.append([_label(k), _num(r["dtheta_mean_deg"], d), _num(r["dtheta_std_deg"]),
                     _num(r["published_deg"]),
                     _num(tgt, d), r["target_source"] if tgt is not None else "-",
                     "-" if m is None else f"{m:+.{digits(m, 0.0, 1, 4)}f} %", r["verdict"], n])
        if r["partial"]:
            cov = r.get("coverage")
            prose.append(f"{_label(k)} is partial: the bag ends inside it"
                         + (f" ({100 * cov:.0f} % of its moving time)" if cov is not None else "")
                         + f": {PARTIAL}.")
        elif tgt is None:
            prose.append(f"{_label(k)}: {NO_TARGET} ({r['target_source']}).")
    if not rows:
        return ["No felt rows: the bag lacks /world/finger, /world/sheet or /fingertip in a stroke."], []
    prose.append(f"Overall: {hl['overall']}.")
    head = ["segment", "felt Δθ mean deg", "std deg", "paper Table I deg", "target deg", "target source",
            "vs target", "verdict", "n"]
    return prose, _table(head, rows)


def _measured(s: dict) -> tuple[list[str], list[str]]:
    keys = row_order(k for k in s if k[:1].isdigit() or k.startswith("stroke_push"))
    prose = ["Measured fingertip (/fingertip) against the true sheet (/world/sheet): the metric of "
             "`flexsheet experiment stroke` (summary.json rows \"10\", \"30\", …). No target.", DD_CONVENTION]
    rows = [[_label(k), _num(s[k]["dtheta_mean_deg"]), _num(s[k]["dtheta_std_deg"]),
             _num(s[k].get("dd_2r_mean_mm")),
             _num(s[k]["dd_mean_mm"]), str(s[k]["n"])] for k in keys]
    head = ["segment", "Δθ mean deg", "Δθ std deg", "Δd 2R mm", "Δd R mm", "n"]
    return prose, _table(head, rows) if rows else []


def _paper_method(s: dict) -> tuple[list[str], list[str]]:
    t1 = s.get("table1", {})
    pm, v = t1.get("paper", {}), t1.get("verdicts", {})
    prose = ["The paper's own method: the measured fingertip against the sheet the display believes (its "
             "kinematics on the joint readback). A secondary check, not the headline: target paper Table I ÷ "
             f"{TARGET_FACTOR:g} (TARGET_FACTOR in {_TARGETS_AT})."]
    rows = []
    for k in row_order(pm):
        tgt = t1["targets"]["paper"][k] if f"paper.{k}" in v else None
        d = digits(pm[k]["dtheta_mean_deg"], tgt)
        rows.append([_label(k), _num(pm[k]["dtheta_mean_deg"], d),
                     _num(PAPER_TABLE1[k]["dtheta_mean_deg"] if tgt is not None else None), _num(tgt, d),
                     f"paper Table I ÷ {TARGET_FACTOR:g}" if tgt is not None else "-",
                     v.get(f"paper.{k}", NO_TARGET), str(pm[k]["n"])])
    head = ["segment", "Δθ mean deg", "paper Table I deg", "target deg", "target source", "verdict", "n"]
    return prose, _table(head, rows) if rows else []


def _decomposition(s: dict) -> tuple[list[str], list[str]]:
    t1 = s.get("table1", {})
    dc, felt = t1.get("decomposition", {}), t1.get("felt", {})
    prose = ["What the felt error is made of, mean angles in deg: tremor (the true finger against its 0.21 s "
             "average), camera (measured against true fingertip), prediction (predicted against true at the "
             "horizon), kinematics (believed against true sheet), slow finger (the felt error without the "
             "tremor)."]
    names = ("tremor", "camera", "prediction", "kinematics", "slow_finger")
    rows = [[_label(k), *(_num(dc[k].get(n)) for n in names), _num(felt.get(k, {}).get("angle3d_mean_deg")),
             _num(felt.get(k, {}).get("gap_mean_mm"))] for k in row_order(dc)]
    head = ["segment", "tremor", "camera", "prediction", "kinematics", "slow finger", "felt 3-D deg",
            "felt gap mm"]
    for k in row_order(t1.get("by_status", {})):
        parts = sorted(t1["by_status"][k].items(), key=lambda kv: -kv[1]["of_mean"])
        prose.append(f"By the planner's status ({_label(k)}): " + "; ".join(
            f"{c} {100 * v['share']:.0f} % of samples, {100 * v['of_mean']:.0f} % of the felt mean "
            f"({v['mean_deg']:.2f}° there)" for c, v in parts) + ".")
    return prose, _table(head, rows) if rows else []


def _delay(s: dict) -> tuple[list[str], list[str]]:
    lat = s.get("latency_ms", {})
    c = lat.get("chain", {}).get("exposure_to_sheet_at_pose", {})
    arm = lat.get("chain", {}).get("exposure_to_arm_command", {})
    basis = lat.get("basis", {}).get("exposure_to_sheet_at_pose", {}).get("basis", "from the nodes' stamps")
    out = ["The delay: exposure → sheet at its pose: not measured (the bag lacks the arms' targets or joint "
           "states)."]
    if c.get("median") is not None:
        share = lat.get("sheet_at_pose_reached")
        reached = (f" ({100 * share:.0f} %; the others never got there before the next target)" if share
                   else "")
        out[0] = (f"The delay: exposure → sheet at its pose, median {c['median']:.1f} ms (p99 {c['p99']:.1f} "
                  f"ms, {basis}; latency chain `exposure_to_sheet_at_pose`): until both clamps' readback is "
                  f"within {POSE_TOL_M * 1e3:g} mm and 0.05° of that sample's target, for {c['n']} of "
                  f"{arm.get('n', '?')} samples{reached}.")
    dl = s.get("delay", {})
    if dl:
        v = dl.get("stroke_speed_mm_per_s")
        tol = (f" At this stroke's {v:.1f} mm/s the chain's {POSE_TOL_M * 1e3:g} mm tolerance is "
               f"{POSE_TOL_M * 1e6 / v:.0f} ms of travel: the chain stops the clock that much before the "
               "exact pose, and counts only the samples the clamps reached.") if v else ""
        out.append(f"Not a second delay, the prediction check (segment {_label(dl['segment'])}): the true "
                   f"sheet trails the true finger by {dl['residual_lag_ms']:+.1f} ms beyond the prediction's "
                   f"{dl['horizon_ms']:.1f} ms lead (fitted; mean angle {dl['angle_at_best_deg']:.3f}° at "
                   f"best), so a horizon of {dl['exposure_to_sheet_ms']:.1f} ms would cancel it "
                   "(`delay.exposure_to_sheet_ms`)."
                   + tol)
    return out, []


def _softness(s: dict) -> tuple[list[str], list[str]]:
    comp = s.get("compliance", {})
    soft = comp.get("felt", {})
    if not soft:
        return ["No press of 2 mm or more with both the true sheet's force (/world/contact) and the object's "
                "request in the bag: no verdict."], []
    r = soft["ratio"]
    basis = ("the object's force-depth from its FEM (/object/force_depth) at the contact on the surface (the "
             "dent's bottom moved back out along the sheet's normal) and the true sheet depth, mapped as the "
             "planner maps it (stiffness_scale, contrast_gain)" if soft.get("basis") == "force_depth" else
             "the virtual object's force at the display's fingertip (/object/deformation contact_force × "
             "stiffness_scale)")
    into = "the object" if soft.get("gate") == "object_depth" else "the sheet"
    prose = [f"While the finger presses (≥ 2 mm into {into}): the finger's contact force on the true sheet "
             "(/world/contact force: the twin's sheet FEM, not the planner's model) against " + basis
             + ". A ratio "
             "within 1 ± 0.15 goes unnoticed (Weber fraction, Bergmann Tiest & Kappers 2009). Saturated: "
             "share of touching targets whose request the sheet could not present (target ≤ 5 %)."]
    sat = comp.get("saturated")
    row = [str(soft["n"]), f"{r['median']:.2f} [{r['p5']:.2f}, {r['p95']:.2f}]",
           f"{100 * soft['within_15pct']:.0f} %",
           f"{soft['felt_n']:.2f}", f"{soft['requested_n']:.2f}",
           "-" if sat is None else f"{100 * sat:.1f} %",
           "≥ 95 % within", soft["verdict"]]
    head = ["n", "felt / requested, median [p5, p95]", "within 15 %", "felt N", "requested N", "saturated",
            "target", "verdict"]
    pp = soft.get("per_press")
    if pp:
        prose.append(f"Per press (one contiguous touch, its median ratio): {pp['n']} press(es), "
                     f"{100 * pp['within_15pct']:.0f} % within 15 %, median {pp['ratio_median']:.2f}, worst "
                     f"{pp['worst']:.2f}.")
    ic = comp.get("inclusion_contrast")
    if ic:
        prose.append("The inclusion, felt from true forces at matched depth (over its footprint against "
                     f"around it, {len(ic['bins'])} depth bins): {100 * ic['felt']:+.1f} %; the object asks "
                     f"{100 * ic['requested']:+.1f} %, the mapped request {100 * ic['mapped']:+.1f} %"
                     + (f" (contrast_gain {', '.join(f'{g:g}' for g in ic['contrast_gain'])})."
                        if ic.get("contrast_gain") else "."))
    mc = comp.get("model_error_contacts")
    if mc:
        prose.append(f"At this run's {mc['contacts']} contact positions on the sheet, over the same strains: "
                     f"median {mc['median_pct']:.1f} %, p90 {mc['p90_pct']:.1f} % (target ≤ "
                     f"{mc['target_pct']:g} % at p90: "
                     f"{'met' if mc['p90_pct'] <= mc['target_pct'] else 'MISSED'}).")
    me = comp.get("model_error")
    if me:
        prose.append(f"The planner's identified sheet model against the true force over clamp strains "
                     f"{me['strains'][0]:g}–{me['strains'][1]:g}: median {me['median_pct']:.1f} % (target ≤ "
                     f"{me['target_pct']:g} %: {'met' if me['median_pct'] <= me['target_pct'] else 'MISSED'}"
                     f"), p90 {me['p90_pct']:.1f} %.")
    sh = s.get("sheet", {})
    if sh:
        prose.append(f"The true sheet: clamp strain at most {sh['strain_true_max']:.3f} (limit 0.30), at "
                     f"most {sh['strain_over_plan_max']:+.3f} over the plan (limit +0.02); one arm holding "
                     f"while the other follows: {sh['one_arm_holds']} joint-state cycles (target 0): "
                     f"{sh['verdict']}.")
        if "span_error_mm" in sh:
            se = sh["span_error_mm"]
            prose.append(f"The clamp span against the planned motion: median {se['median']:.2f} mm, p99 "
                         f"{se['p99']:.2f} mm (target ≤ 1.0), max {se['max']:.2f} mm; guard cycles "
                         f"{sh['guard_waits']} (target 0): {sh['motion_verdict']}.")
        pd, sk = sh.get("path_dev_mm", {}), sh.get("arrival_skew_ms", {})
        if pd.get("n"):
            skew = (f"the two clamps' lag behind it differs by p99 {sk['p99']:.0f} ms while the sheet moves"
                    if sk.get("n") else "the sheet never moved fast enough to compare the clamps' lags")
            prose.append(f"Each clamp against the motion at the same instant: p99 {pd['p99']:.2f} mm, max "
                         f"{pd['max']:.2f} mm; {skew}.")
    return prose, _table(head, [row])


def _placement(s: dict) -> tuple[list[str], list[str]]:
    pl = s.get("placement", {})
    if not pl:
        return ["No touching sample with the true finger, the true sheet and the scene: no verdict."], []
    prose = ["While the finger touches (inside the object, or behind the true sheet while the world says it "
             "touches): the true sheet's plane ahead (+) or behind (−) the object's surface under the true "
             "finger, "
             "along the object's normal, mm; per touch, the sheet's arrival at the surface under the finger "
             f"(within {pl['targets']['arrival_tol_mm']:g} mm behind it, or ahead) against the finger's "
             "arrival there, ms (negative: the sheet waited)."]
    d, a = pl["distance_mm"] or {"p50": math.nan, "p99": math.nan, "max": math.nan}, pl.get("arrival_ms")
    rows = [["|distance|, mm", f"{d['p50']:.2f}", f"{d['p99']:.2f}", f"{d['max']:.2f}",
             f"≤ {pl['targets']['distance_mm.p99']:g} p99", pl["verdicts"]["distance"]]]
    hy, da = pl.get("head_yield"), pl.get("distance_mm_all")
    if hy and hy["n"] and da:
        prose.append("The sheet yielded to the viewer's head (a keep_out plan, until back at the object's "
                     f"surface) in {hy['n']} touching samples ({100 * hy['share']:.1f} %); they are left out "
                     f"of the distance verdict. Over every touching sample: p99 {da['p99']:.2f} mm, max "
                     f"{da['max']:.2f} mm.")
    sp = pl.get("split")
    if sp and all(v is not None for v in sp["share"].values()):
        prose.append(f"The {sp['n']} samples beyond the target, split (shares of their summed distance, they "
                     f"add to 100 %): the arms off the plan's pose {100 * sp['share']['arms']:.0f} %, the "
                     f"plan's pose off its contact (limited or held) {100 * sp['share']['plan_pose']:.0f} %, "
                     f"the planned contact off the object's surface {100 * sp['share']['contact']:.0f} %.")
    first = "-" if pl["sheet_first"] is None else f"{100 * pl['sheet_first']:.0f} % of {pl['arrivals']}"
    rows.append(["sheet first, touches", first, "-", "-", f"≥ {100 * pl['targets']['sheet_first']:.0f} %",
                 pl["verdicts"]["sheet_first"]])
    on = pl.get("onsets")
    if on and on["n"]:
        rows.append([f"onsets in place and ≤ {pl['targets']['arrival_angle_deg']:g}°",
                     f"{100 * on['in_place_and_pose']:.0f} % of {on['n']}",
                     f"{on['angle_deg']['median']:.1f}°",
                     f"{on['angle_deg']['max']:.1f}°", f"≥ {100 * pl['targets']['onsets']:.0f} %",
                     pl["verdicts"]["onsets"]])
    if a:
        rows.append(["sheet − finger arrival, ms", f"{a['median']:.0f}", f"{a['p99']:.0f}", f"{a['max']:.0f}",
                     "≤ 0",
                     "-"])
    phases = ", ".join(f"{k} p99 {v['p99']:.2f} mm (n {v['n']})" for k,
                       v in pl.get("by_phase_mm", {}).items())
    if phases:
        prose.append(f"By the script's phase: {phases}.")
    if pl.get("never") or pl.get("no_finger_arrival"):
        prose.append(f"Touches whose sheet never arrived: {pl['never']}; touches that never pushed into the "
                     f"object (the sheet ahead): {pl['no_finger_arrival']}.")
    return prose, _table(["figure", "p50", "p99", "max", "target", "verdict"], rows)


def _compliance(s: dict) -> tuple[list[str], list[str]]:
    comp = s.get("compliance", {})
    if not comp:
        return ["No touching sheet targets in the bag."], []
    f = "{0[median]:.1f} [{0[p5]:.1f}, {0[p95]:.1f}]".format
    rows = []
    comp = {k: b for k, b in comp.items() if isinstance(b, dict) and "tension_n_per_m" in b}   # the segments
    for key in ["all", *row_order(k for k in comp if k != "all")]:
        b = comp[key]
        sc = b.get("stiffness_scale")
        un = b.get("object_stiffness_unscaled_n_per_m")
        rows.append([key if key == "all" else _label(key), f(b["tension_n_per_m"]), f(b["stiffness_n_per_m"]),
                     f(b["object_stiffness_n_per_m"]),
                     "not recorded" if sc is None else ", ".join(f"{x:g}" for x in sc),
                     "-" if un is None else f(un), f"{100 * b['at_limit']:.0f} %"])
    prose = ["The sheet at the contacts (/sheet/target while touching), median [p5, p95], N/m. Requested = "
             "the "
             "object's stiffness × stiffness_scale (the planner's, from its heartbeat in /diagnostics); the "
             "object's own stiffness is the request ÷ that scale. At limit: share of targets whose request "
             "the sheet could not present."]
    scaled = {x for b in comp.values() for x in (b.get("stiffness_scale") or []) if x != 1.0}
    if scaled:
        prose.append(f"Scaled: stiffness_scale {', '.join(f'{x:g}' for x in sorted(scaled))}: the requested "
                     "column is the scaled request, not the object's stiffness.")
    head = ["segment", "tension", "presented k", "requested k (scaled)", "stiffness_scale",
            "object k (unscaled)",
            "at limit"]
    return prose, _table(head, rows)


def _latency(s: dict) -> tuple[list[str], list[str]]:
    lat = s.get("latency_ms", {})
    basis, tg = lat.get("basis", {}), lat.get("targets", {})
    rows = []
    for k, v in lat.get("chain", {}).items():
        t = tg.get(k, {})
        rows.append([k, _num(v["median"], 2), _num(v["p99"], 2), str(v["n"]),
                     basis.get(k, {}).get("basis", "?"),
                     f"≤ {t['target_ms']:g}" if t else "-", t.get("verdict", "-")])
    prose = ["One chain per fingertip sample from the stamps the nodes set, ms. Modelled: the lab's declared "
             "timings (flexsheet/model/timing.py) charged on the simulated clock, a constant per hop where "
             "nothing else varies (p99 = median); measured: the nodes' stamps on this host's clock."]
    if tg:
        prose.append("Targets: " + ", ".join(f"{k} ≤ {t['target_ms']:g} ms median" for k, t in tg.items())
                     + f", {next(iter(tg.values()))['source']}.")
    prose += [f"- {k}: {b['basis']}, {b.get('how', '')}" for k, b in basis.items()]
    head = ["hop", "median ms", "p99 ms", "n", "basis", "target ms", "verdict"]
    return prose, _table(head, rows) if rows else []


def _head(s: dict) -> tuple[list[str], list[str]]:
    eye, view, safety = s.get("eye", {}), s.get("view", {}), s.get("safety", {})
    if not (eye or view or safety):
        return ["No /world/head in the bag (no moving head in this run): no verdict."], []
    prose = ["The image is corrected for the tracked eyes (/eye/pose). View error: where the true eyes see "
             "the object's points on the true sheet against where they belong, on the imaginary screen, in "
             "projector px (the same frames judged as if drawn for the fixed V beside it). Eye error: "
             "/eye/pose against the true eyes. Keep-out: the true sheet's distance from the true head "
             "sphere."]
    rows = []
    if eye.get("error_mm"):
        e = eye["error_mm"]
        rows.append(["eye error, mm", f"{e['median']:.2f}", f"{e['p95']:.2f}",
                     f"≤ {eye['target_mm']:g} median",
                     eye["verdict"]])
    for kind in ("tracked", "fixed"):
        if kind in view:
            v = view[kind]
            rows.append([f"view error, {kind}, px", f"{v['error_px_median']:.2f}", f"{v['error_px_p95']:.2f}",
                         "≤ 1 median, ≤ 2 p95" if kind == "tracked" else "(comparison)",
                         view["verdict"] if kind == "tracked" else "-"])
    if safety:
        rows.append(["sheet from head sphere, m (min)", f"{safety['min_head_distance_m']:.3f}", "-",
                     f"≥ {safety['margin_m']:g}", "met" if safety["min_head_distance_m"] >= safety["margin_m"]
                     else "MISSED"])
        rows.append(["keep-out violations (samples)", str(safety["keepout_violations"]), "-", "0",
                     "met" if safety["keepout_violations"] == 0 else "MISSED"])
        rows.append(["sheet speed near the head, m/s (max)", f"{safety['max_speed_near_head_mps']:.3f}", "-",
                     "≤ 0.25", "met" if safety["max_speed_near_head_mps"] <= 0.25 else "MISSED"])
        for sp in safety.get("head_lost", {}).get("spans", []):
            after = "never" if sp["hold_after_ms"] is None else f"{sp['hold_after_ms']:.1f}"
            rows.append([f"glasses lost {sp['duration_s']:.1f} s: planner held after, ms", after,
                         f"step {sp['hold_step_mm_max']:.2f} mm", "≤ 16.7, no step",
                         safety["head_lost"]["verdict"]])
    return prose, _table(["figure", "median", "p95", "target", "verdict"], rows)


def sections(summary: dict) -> list[tuple[str, list[str], list[str]]]:
    """(heading, prose lines, table lines) of each part of the report; the first has no heading."""
    return [("", _header(summary), []),
            ("Table I — felt Δθ, the headline", *_headline(summary)),
            ("Table I — measured fingertip vs true sheet (not the headline)", *_measured(summary)),
            ("Table I — the paper's method (not the headline)", *_paper_method(summary)),
            ("Table I — what the felt error is made of", *_decomposition(summary)),
            ("Delay — exposure → sheet at its pose", *_delay(summary)),
            ("Softness felt — the true sheet's force against the object's", *_softness(summary)),
            ("Placement — the true sheet against the object's surface under the finger",
             *_placement(summary)),
            ("The viewer's head — tracked image and keep-out", *_head(summary)),
            ("Sheet tension and stiffness at the contacts (the planner's model)", *_compliance(summary)),
            ("Latency per hop and end to end", *_latency(summary))]


def format_text(summary: dict) -> str:
    """The report as plain text (the terminal)."""
    out: list[str] = []
    for head, prose, table in sections(summary):
        if head:
            out += ["", head, "-" * len(head)]
        out += prose + ([""] + table if table else [])
    return "\n".join(out)


def markdown(summary: dict, title: str = "flexsheet run report", charts=CHARTS) -> str:
    """``report.md``: headings, prose, the tables as code blocks, then ``charts`` ((file, caption) pairs)."""
    out = [f"# {title}", ""]
    for head, prose, table in sections(summary):
        if head:
            out += [f"## {head}", ""]
        out += [p if p.startswith("- ") else p + "  " for p in prose] + [""]
        if table:
            out += ["```", *table, "```", ""]
    out += ["## Charts", "", *(f"![{cap}]({f})\n" for f, cap in charts)]
    return "\n".join(out)
