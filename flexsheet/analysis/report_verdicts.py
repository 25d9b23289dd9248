"""Verdicts of a run report (:mod:`flexsheet.analysis.report`): each judged on the unrounded numbers.

* Table I, the headline: the *felt* Δθ mean of each segment against paper Table I ÷
  :data:`~flexsheet.analysis.table1.FELT_TARGET_FACTOR` (:func:`flexsheet.analysis.table1.target`); met when
  mean ≤ target. Targets exist for the paper's rows (10 s, 30 s) on the paper's cylinder only.
* A partial segment (the bag ends inside it) gets :data:`PARTIAL`; a partial run gets no overall verdict
  and no latency verdicts (its complete segments keep theirs).
* Latency: the medians of the chain's ends against :data:`LATENCY_TARGETS_MS`.
* Softness and placement are judged where they are measured (:mod:`flexsheet.analysis.report_softness`, "met"
  or "MISSED" on the unrounded numbers, a partial run included): ``compliance.felt.verdict`` (share of samples
  within the Weber fraction), ``placement.verdicts`` {distance (p99 |distance| mm), sheet_first (share of
  touches)} and ``placement.verdict`` (both met).
"""

from __future__ import annotations

from flexsheet.analysis.table1 import FELT_TARGET_FACTOR, PAPER_TABLE1

__all__ = ["PARTIAL", "NO_TARGET", "table1_verdicts", "judge", "headline", "row_order", "digits",
           "HEADLINE_METRIC", "LATENCY_TARGETS_MS", "LATENCY_TARGET_SOURCE"]

#: the lab's latency budget, median ms, per end of the chain
LATENCY_TARGETS_MS = {"exposure_to_arm_command": 15.0, "exposure_to_projected": 25.0}
LATENCY_TARGET_SOURCE = "the lab's latency budget (docs/realtime.md)"
#: the verdict of a partial segment or run
PARTIAL = "partial — no verdict"
#: the verdict of a row without a target
NO_TARGET = "no target"
#: what the headline figure is
HEADLINE_METRIC = ("felt Δθ: the angle between the object's normal at the true fingertip (/world/finger, at "
                   "each exposure) and the true sheet (/world/sheet), in the stroke's normal section (paper "
                   "Fig. 9)")


def _verdict(value: float, tgt: float | None, partial: bool) -> str:
    if partial:
        return PARTIAL
    if tgt is None:
        return NO_TARGET
    return "met" if value <= tgt else "MISSED"


def table1_verdicts(t1: dict, segments: dict, paper_scene: bool) -> dict[str, str]:
    """``{"felt.10": "met" | "MISSED" | PARTIAL, "paper.10": …}`` for the paper's rows measured in ``t1``
    (``felt``, ``paper``, ``targets``) on the paper's cylinder (``paper_scene``); none on another scene."""
    if not paper_scene:
        return {}
    return {f"{kind}.{k}": _verdict(t1[kind][k]["dtheta_mean_deg"], t1["targets"][kind][k],
                                    bool(segments.get(k, {}).get("partial")))
            for kind in ("felt", "paper") for k in PAPER_TABLE1 if k in t1.get(kind, {})}


def row_order(keys) -> list[str]:
    """Table I row keys in reading order: the strokes by moving time, then the others by name."""
    def rank(k: str):
        try:
            return (0, float(k), k)
        except ValueError:
            return (1, 0.0, k)
    return sorted(keys, key=rank)


def headline(summary: dict) -> dict:
    """The headline of a run: ``{"metric", "target_source", "rows": {key: {"dtheta_mean_deg",
    "dtheta_std_deg", "published_deg" (paper Table I), "target_deg", "target_source", "verdict", "margin_pct"
    ((mean − target) / target, %), "n", "expected_n", "coverage", "partial"}}, "overall"}``."""
    t1 = summary.get("table1", {})
    felt, verdicts = t1.get("felt", {}), t1.get("verdicts", {})
    segs = summary.get("segments", {})
    src = t1.get("target_source", {}).get("felt", f"paper Table I ÷ {FELT_TARGET_FACTOR:g}")
    rows = {}
    for k in row_order(felt):
        r, seg = felt[k], segs.get(k, {})
        judged = f"felt.{k}" in verdicts
        tgt = t1["targets"]["felt"][k] if judged else None
        partial = bool(seg.get("partial"))
        if judged:
            verdict, why = verdicts[f"felt.{k}"], src
        else:
            verdict = PARTIAL if partial else NO_TARGET
            why = "none: paper Table I has no such row" if k not in PAPER_TABLE1 else \
                "none: paper Table I is the paper's cylinder, not this scene"
        rows[k] = {"dtheta_mean_deg": r["dtheta_mean_deg"], "dtheta_std_deg": r["dtheta_std_deg"],
                   "published_deg": PAPER_TABLE1[k]["dtheta_mean_deg"] if judged else None,
                   "target_deg": tgt, "target_source": why, "verdict": verdict,
                   "margin_pct": 100.0 * (r["dtheta_mean_deg"] - tgt) / tgt if tgt else None,
                   "n": r["n"], "expected_n": seg.get("expected_n"), "coverage": seg.get("coverage"),
                   "partial": partial}
    judged = [r["verdict"] for r in rows.values() if r["verdict"] in ("met", "MISSED")]
    if summary.get("run", {}).get("partial"):
        overall = PARTIAL
    elif not judged:
        overall = NO_TARGET
    else:
        overall = "met" if all(v == "met" for v in judged) else "MISSED"
    return {"metric": HEADLINE_METRIC, "target_source": src, "rows": rows, "overall": overall}


def _latency_targets(summary: dict) -> dict:

    chain = summary.get("latency_ms", {}).get("chain", {})
    partial = bool(summary.get("run", {}).get("partial"))
    out = {}
    for hop, tgt in LATENCY_TARGETS_MS.items():
        med = chain.get(hop, {}).get("median")
        if med is None:
            continue
        out[hop] = {"target_ms": tgt, "source": LATENCY_TARGET_SOURCE, "verdict": _verdict(med, tgt, partial)}
    return out


def judge(summary: dict) -> dict:
    """Add ``headline`` (:func:`headline`) and ``latency_ms.targets`` (hop → ``{"target_ms", "source",
    "verdict"}``) to ``summary``; returns it."""
    summary["headline"] = headline(summary)
    if "latency_ms" in summary:
        summary["latency_ms"]["targets"] = _latency_targets(summary)
    return summary


def digits(value: float, ref: float | None, base: int = 3, most: int = 6) -> int:
    """Decimals that tell ``value`` from ``ref``: ``base``, more where both round alike, at most ``most``."""
    d = base
    while ref is not None and value != ref and d < most and f"{value:.{d}f}" == f"{ref:.{d}f}":
        d += 1
    return d
