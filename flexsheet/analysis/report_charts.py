"""Charts of a run report (:mod:`flexsheet.analysis.report`): matplotlib Agg PNGs, each with a JSON of the
same numbers beside it (``table1.json``, ``felt.json``, ``latency.json``, ``graph.json``,
``compliance.json``). Each metric chart has a title, units (deg for angles, mm for lengths, ms for times), the
target, the verdict and this scene's own rows; the paper's published bars only on the paper's cylinder."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from flexsheet.analysis.report_verdicts import HEADLINE_METRIC, digits
from flexsheet.analysis.table1 import PAPER_TABLE1

__all__ = ["table1_chart", "felt_chart", "latency_chart", "graph_chart", "compliance_chart", "spread"]


def _plt():
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt


def spread(mean: float, std: float) -> tuple[float, float]:
    """(lower, upper) of mean ± std, the lower clipped at 0 (errors are ≥ 0)."""
    return max(0.0, mean - std), mean + std


def _table1_data(summary: dict) -> dict:
    hl = summary.get("headline", {})
    felt = summary.get("table1", {}).get("felt", {})
    scene = summary.get("scene", {}).get("name", "cylinder")
    rows = {}
    for k, r in hl.get("rows", {}).items():
        f = felt[k]
        paper = r["published_deg"] is not None
        dd, dd_sd = (f["dd_2r_mean_mm"], f["dd_2r_std_mm"]) if paper and "dd_2r_mean_mm" in f else \
            (f["dd_mean_mm"], f["dd_std_mm"])
        rows[k] = {"dtheta_mean_deg": r["dtheta_mean_deg"], "dtheta_std_deg": r["dtheta_std_deg"],
                   "dtheta_spread_deg": spread(r["dtheta_mean_deg"], r["dtheta_std_deg"]),
                   "published_deg": r["published_deg"], "target_deg": r["target_deg"],
                   "target_source": r["target_source"], "verdict": r["verdict"], "partial": r["partial"],
                   "n": r["n"],
                   "dd_mm": dd, "dd_spread_mm": spread(dd, dd_sd),
                   "dd_convention": "2R·Δθ (the paper's)" if paper else "|DD′| chord",
                   "published_dd_mm": PAPER_TABLE1[k]["dd_mean_mm"] if paper else None}
    return {"title": f"Table I headline: felt Δθ per segment, scene {scene}", "metric": HEADLINE_METRIC,
            "units": {"dtheta": "deg", "dd": "mm"}, "spread": "mean ± 1 s.d., clipped at 0",
            "verdict_on": "Δθ mean (no Δd target)", "overall": hl.get("overall"), "rows": rows}


def _verdict_marks(ax, rows: dict, tops: list[float]) -> None:
    """The target line over each row that has one, and the verdict with the two numbers above each row."""
    first = next((i for i, r in enumerate(rows.values()) if r["target_deg"] is not None), None)
    for i, r in enumerate(rows.values()):
        if r["target_deg"] is not None:
            ax.hlines(r["target_deg"], i - 0.45, i + 0.45, color="k", ls="--", lw=1.2,
                      label=f"target ({r['target_source']})" if i == first else None)
        d = digits(r["dtheta_mean_deg"], r["target_deg"])
        vs = "" if r["target_deg"] is None else f" vs {r['target_deg']:.{d}f}°"
        ax.text(i, tops[i] * 1.03, f"{r['verdict']}\n{r['dtheta_mean_deg']:.{d}f}°{vs}", ha="center",
                va="bottom",
                fontsize=7, color="#b00" if r["verdict"] == "MISSED" else "k")


def table1_chart(summary: dict, path: Path) -> dict:
    """Felt Δθ (deg) and Δd (mm) per segment of this scene, with the target, the verdict and (paper's cylinder
    only) the paper's published row. Writes ``path`` (PNG, when there are rows) and its JSON; returns the
    data."""
    data = _table1_data(summary)
    path.with_suffix(".json").write_text(json.dumps(data, indent=1))
    rows = data["rows"]
    if not rows:
        return data
    plt = _plt()
    keys = list(rows)
    x = np.arange(len(keys))
    paper = any(r["published_deg"] is not None for r in rows.values())
    w = 0.38 if paper else 0.6
    fig, axes = plt.subplots(1, 2, figsize=(10, 4.2))
    for ax, (q, label) in zip(axes, (("dtheta", "Δθ mean (deg)"), ("dd", "Δd mean (mm)")), strict=True):
        mean = [r["dtheta_mean_deg"] if q == "dtheta" else r["dd_mm"] for r in rows.values()]
        lo_hi = [r["dtheta_spread_deg"] if q == "dtheta" else r["dd_spread_mm"] for r in rows.values()]
        pub = [r["published_deg"] if q == "dtheta" else r["published_dd_mm"] for r in rows.values()]
        err = np.array([[m - lo for m, (lo, _) in zip(mean, lo_hi, strict=True)],
                        [hi - m for m, (_, hi) in zip(mean, lo_hi, strict=True)]])
        bars = ax.bar(x - w / 2 if paper else x, mean, w, yerr=err, capsize=3,
                      label="this run, felt (± 1 s.d., clipped at 0)")
        for b, r in zip(bars, rows.values(), strict=True):
            if r["partial"]:
                b.set_hatch("//")
                b.set_alpha(0.5)
        if paper:
            ax.bar(x + w / 2, [np.nan if p is None else p for p in pub], w, color="#bbbbbb",
                   label="paper Table I (the paper's cylinder)")
        if q == "dtheta":
            _verdict_marks(ax, rows, [max(hi, p or 0.0) for (_, hi), p in zip(lo_hi, pub, strict=True)])
        ax.set_xticks(x, [f"{k} s" + (" (partial)" if rows[k]["partial"] else "") for k in keys], fontsize=8)
        ax.set_xlabel("segment (moving time)")
        ax.set_ylabel(label if q == "dtheta" else f"{label}, {next(iter(rows.values()))['dd_convention']}")
        ax.set_ylim(0.0, 1.6 * max([hi for _, hi in lo_hi] + [p for p in pub if p is not None]))
        untargeted = all(r["target_deg"] is None for r in rows.values())
        sub = f"Δθ: {next(iter(rows.values()))['target_source']}" if untargeted else "Δθ: verdict per segment"
        ax.set_title(sub if q == "dtheta" else "Δd: no target (verdicts are on Δθ)", fontsize=9)
        ax.legend(fontsize=7, loc="upper left")
    fig.suptitle(f"{data['title']}: {data['overall']}", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return data


def felt_chart(summary: dict, series: dict, path: Path) -> dict:
    """Felt Δθ (deg) per exposure over each stroking segment (the paper's method beside it, for context) with
    the target line and the verdict in each title. Writes ``path`` (PNG) and its JSON; returns the data."""
    t1 = summary.get("table1", {})
    rows = summary.get("headline", {}).get("rows", {})
    keys = [k for k in rows if k in series]
    scene = summary.get("scene", {}).get("name", "cylinder")
    data = {"title": f"Felt Δθ over each segment, scene {scene}", "unit": "deg", "metric": HEADLINE_METRIC,
            "targets": {k: rows[k]["target_deg"] for k in keys},
            "target_source": {k: rows[k]["target_source"] for k in keys},
            "verdicts": {k: rows[k]["verdict"] for k in keys}, "delay": summary.get("delay", {}),
            "means": {k: {"felt": rows[k]["dtheta_mean_deg"],
                          "paper_method": t1.get("paper", {}).get(k, {}).get("dtheta_mean_deg")}
                      for k in keys},
            "series": {k: series[k] for k in keys}}
    path.with_suffix(".json").write_text(json.dumps(data))
    if not keys:
        return data
    plt = _plt()
    fig, axes = plt.subplots(1, len(keys), figsize=(4.6 * len(keys), 3.8), squeeze=False)
    for ax, k in zip(axes[0], keys, strict=True):
        sr, r = series[k], rows[k]
        ax.plot(sr["t_s"], sr["felt_deg"], lw=0.6, label="felt (true finger vs true sheet)")
        if "paper_deg" in sr:
            ax.plot(sr["t_s"], sr["paper_deg"], lw=0.5, alpha=0.5, color="#888888",
                    label="paper's method (context)")
        if r["target_deg"] is not None:
            ax.axhline(r["target_deg"], color="k", ls="--", lw=1.0, label=f"target: {r['target_source']}")
        ax.axhline(r["dtheta_mean_deg"], color="C0", ls=":", lw=1.0, label="felt mean")
        d = digits(r["dtheta_mean_deg"], r["target_deg"])
        tgt = "no target" if r["target_deg"] is None else f"target {r['target_deg']:.{d}f}°"
        ax.set_title(f"{k} s{' (partial)' if r['partial'] else ''}: mean {r['dtheta_mean_deg']:.{d}f}°, "
                     f"{tgt}\nverdict: {r['verdict']}", fontsize=8)
        ax.set_xlabel("time in segment (s)")
        ax.set_ylabel("Δθ (deg)")
        ax.set_ylim(bottom=0.0)
        ax.legend(fontsize=6)
    fig.suptitle(data["title"], fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return data


def compliance_chart(summary: dict, series: dict, path: Path) -> dict:
    """The force the finger felt (``/world/contact``) against the mapped request at the same depth, per
    pressed sample, with the ±15 % band, the target and the verdict (``summary["compliance"]["felt"]``).
    Writes ``path`` (PNG, when there are samples) and its JSON; returns the data."""
    felt = (summary.get("compliance") or {}).get("felt") or {}
    smp = series.get("compliance") or {}
    data = {"title": "Force felt against force requested, while pressed >= 2 mm",
            "unit": {"force": "N", "depth": "mm"},
            "target": felt.get("target"), "verdict": felt.get("verdict"),
            "within_15pct": felt.get("within_15pct"),
            "basis": felt.get("basis"),
            "depth_mm": [1e3 * x for x in smp.get("depth_m", [])], "felt_n": smp.get("felt_n", []),
            "requested_n": smp.get("requested_n", [])}
    path.with_suffix(".json").write_text(json.dumps(data, indent=1))
    if not data["felt_n"]:
        return data
    plt = _plt()
    d, f, r = (np.asarray(data[k], float) for k in ("depth_mm", "felt_n", "requested_n"))
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(11, 4.2))
    a1.scatter(d, r, s=6, color="k", label="requested (mapped object)")
    a1.scatter(d, f, s=6, color="tab:blue", label="felt (true sheet)")
    a1.set_xlabel("indentation, mm")
    a1.set_ylabel("force, N")
    a1.legend(fontsize=7)
    a1.set_title("force-depth along the presses", fontsize=8)
    a2.scatter(d, f / r, s=6, color="tab:blue")
    a2.axhspan(0.85, 1.15, color="tab:green", alpha=0.15, label="±15 % (Weber fraction)")
    a2.set_xlabel("indentation, mm")
    a2.set_ylabel("felt / requested")
    a2.legend(fontsize=7)
    w = data["within_15pct"]
    a2.set_title(f"{100 * w:.0f} % within ±15 % (target >= 95 %): {data['verdict']}", fontsize=8)
    fig.suptitle(data["title"], fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return data


def latency_chart(summary: dict, path: Path) -> dict:
    """Median and p99 (ms) per hop, each labelled modelled or measured, with the targets and verdicts of the
    chain's ends. Writes ``path`` (PNG, when there are samples) and its JSON; returns the data."""
    lat = summary.get("latency_ms", {})
    basis, tg = lat.get("basis", {}), lat.get("targets", {})
    chain = {k: v for k, v in lat.get("chain", {}).items() if v["n"]}
    clock = (summary.get("clock") or {}).get("kind", "?") if isinstance(summary.get("clock"), dict) else "?"
    data = {"title": f"Latency per hop and end to end (clock {clock})", "unit": "ms",
            "rows":
                {k: {**v, "basis": basis.get(k, {}).get("basis"), "target_ms": tg.get(k, {}).get("target_ms"),
                     "verdict": tg.get(k, {}).get("verdict")} for k, v in chain.items()},
            "target_source": next(iter(tg.values()))["source"] if tg else None}
    path.with_suffix(".json").write_text(json.dumps(data, indent=1))
    if not chain:
        return data
    plt = _plt()
    names = list(chain)[::-1]
    fig, ax = plt.subplots(figsize=(9, 4.2))
    colour = {"modelled": "#9ecae1", "measured": "#3182bd"}
    rows = data["rows"]
    ax.barh([f"{k} [{rows[k]['basis'] or '?'}]" for k in names], [rows[k]["median"] for k in names],
            color=[colour.get(rows[k]["basis"], "#cccccc") for k in names], label="median")
    ax.scatter([rows[k]["p99"] for k in names], range(len(names)), color="k", marker="|", s=200, label="p99")
    first = True
    for i, k in enumerate(names):
        if rows[k]["target_ms"] is not None:
            ax.vlines(rows[k]["target_ms"], i - 0.4, i + 0.4, color="#b00", lw=1.5,
                      label="target (median)" if first else None)
            ax.text(rows[k]["target_ms"], i + 0.42, f" ≤ {rows[k]['target_ms']:g} ms: {rows[k]['verdict']}",
                    fontsize=7, va="bottom")
            first = False
    ax.tick_params(axis="y", labelsize=7)
    ax.set_xlim(0.0, 1.45 * max(max(v["p99"] for v in rows.values()),
                                *(v["target_ms"] or 0.0 for v in rows.values())))
    ax.set_xlabel("latency (ms)")
    src = f"; targets: {data['target_source']}" if data["target_source"] else ""
    ax.set_title(f"{data['title']}{src}\n[modelled]: the lab's declared timings on the simulated clock; "
                 "[measured]: the nodes' stamps on this host", fontsize=8)
    ax.legend(fontsize=7, loc="upper right")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return data


def graph_chart(heartbeats: list, path: Path) -> dict:
    """Draw the live node/topic graph from recorded heartbeats (each node's last one): nodes on the left and
    right, topics in the middle, an arrow per publisher and subscription. Writes ``path`` (PNG) and
    returns the graph as ``{"nodes": {name: {"host", "publishes", "subscribes"}}}`` (also saved as JSON)."""
    plt = _plt()
    last: dict = {}
    for _, hb in heartbeats:
        last[hb.node] = hb
    graph = {"nodes": {n: {"host": hb.host, "type": hb.node_type,
                           "publishes": sorted(p.topic for p in hb.publishers if p.topic != "/diagnostics"),
                           "subscribes": sorted(sub.topic for sub in hb.subscriptions)}
                       for n, hb in sorted(last.items())}}
    topics = sorted({t for v in graph["nodes"].values() for t in v["publishes"] + v["subscribes"]})
    names = list(graph["nodes"])
    fig, ax = plt.subplots(figsize=(11, max(4.0, 0.42 * max(len(topics), len(names)))))
    ty = {t: i for i, t in enumerate(reversed(topics))}
    ny = {n: i * (len(topics) - 1) / max(1, len(names) - 1) for i, n in enumerate(reversed(names))}
    for n, v in graph["nodes"].items():
        ax.text(0.0, ny[n], f"{n}\n[{v['host']}]", ha="center", va="center", fontsize=8,
                bbox={"boxstyle": "round", "fc": "#dbe9f6"})
        ax.text(2.0, ny[n], n, ha="center", va="center", fontsize=8,
                bbox={"boxstyle": "round", "fc": "#dbe9f6"})
        for t in v["publishes"]:
            ax.annotate("", (0.85, ty[t]), (0.18, ny[n]),
                        arrowprops={"arrowstyle": "->", "color": "#1f77b4", "lw": 0.7})
        for t in v["subscribes"]:
            ax.annotate("", (1.82, ny[n]), (1.15, ty[t]),
                        arrowprops={"arrowstyle": "->", "color": "#ff7f0e", "lw": 0.7})
    for t in topics:
        ax.text(1.0, ty[t], t, ha="center", va="center", fontsize=8,
                bbox={"boxstyle": "square", "fc": "#fff3d6"})
    ax.set_xlim(-0.4, 2.4)
    ax.set_ylim(-1, len(topics))
    ax.axis("off")
    ax.set_title("flexsheet node/topic graph (from the recorded heartbeats): publishers → topics → "
                 "subscribers",
                 fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    path.with_suffix(".json").write_text(json.dumps(graph, indent=1))
    return graph



def head_chart(summary: dict, series: dict, path: Path) -> dict:
    """The viewer's head over the run: the view error per frame (median over the object's points, both eyes'
    worse, px) drawn for the tracked eyes and as if for the fixed V, with the 1 px target; and the true
    sheet's distance from the head sphere with the keep-out margin. Writes ``path`` (PNG) and its JSON;
    returns the data."""
    head = series.get("head") or {}
    vs, cl = head.get("view"), head.get("clearance") or {}
    view, safety = summary.get("view", {}), summary.get("safety", {})
    data = {"title": "The viewer's head: view error and keep-out distance",
            "units": {"view": "px", "distance": "m"},
            "targets": {"view_error_px_median": 1.0, "min_head_distance_m": safety.get("margin_m")},
            "verdicts": {"view": view.get("verdict"), "safety": safety.get("verdict")},
            "t_s": vs["t"] if vs else [], "tracked_px": [max(r) for r in vs["tracked"]] if vs else [],
            "fixed_px": [max(r) for r in vs["fixed"]] if vs else [], "distance_t_s": cl.get("t", []),
            "distance_m": [c + safety.get("margin_m", 0.0) for c in cl.get("clearance_m", [])]}
    path.with_suffix(".json").write_text(json.dumps(data))
    if not data["t_s"] and not data["distance_t_s"]:
        return data
    plt = _plt()
    fig, (a, b) = plt.subplots(2, 1, figsize=(7.5, 5.2), sharex=True)
    t0 = min((data["t_s"] or [0.0])[0], (data["distance_t_s"] or [0.0])[0])
    if data["t_s"]:
        t = [x - t0 for x in data["t_s"]]
        a.plot(t, data["fixed_px"], lw=0.6, color="#999999", label="as if drawn for the fixed V")
        a.plot(t, data["tracked_px"], lw=0.8, label="drawn for the tracked eyes")
        a.axhline(1.0, color="k", ls="--", lw=1.0, label="target: median ≤ 1 px")
        a.set_ylabel("view error, median per frame (px)")
        a.set_title(f"view error: tracked {view.get('tracked', {}).get('error_px_median', float('nan')):.2f} "
                    f"px median, fixed V {view.get('fixed', {}).get('error_px_median', float('nan')):.2f} "
                    f"px; verdict: {view.get('verdict')}", fontsize=8)
        a.legend(fontsize=6)
    if data["distance_t_s"]:
        b.plot([x - t0 for x in data["distance_t_s"]], [1e3 * d for d in data["distance_m"]], lw=0.8,
               label="true sheet to the true head sphere")
        b.axhline(1e3 * safety["margin_m"], color="r", ls="--", lw=1.0, label="keep-out margin")
        b.set_ylabel("distance (mm)")
        b.set_title(f"keep-out: min {1e3 * safety['min_head_distance_m']:.0f} mm, "
                    f"{safety['keepout_violations']} violations, near-head speed "
                    f"{safety['max_speed_near_head_mps']:.3f} m/s; verdict: {safety['verdict']}", fontsize=8)
        b.legend(fontsize=6)
    b.set_xlabel("time in the run (s)")
    fig.suptitle(data["title"], fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return data
