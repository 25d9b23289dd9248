"""Report of a full-graph run, computed from the recorded bag only (``launch/sim.yaml``'s ``report``).

``flexsheet launch FILE --out OUT`` calls :func:`main` after the run; ``python -m flexsheet.analysis.report
OUT`` reports again from an existing ``OUT``. Reads ``OUT/*.mcap`` (the recorder's bag) and writes
``OUT/summary.json``, ``OUT/report.md`` (:mod:`flexsheet.analysis.report_text`) and the charts with JSON
beside them (``table1``, ``felt``, ``latency``, ``graph``: :mod:`flexsheet.analysis.report_charts`), and
prints the report.

* The headline, one per Table I row: the *felt* Δθ (the true fingertip against the true sheet), with the
  paper's published figure, the target (paper Table I ÷ 2) and the verdict
  (:mod:`flexsheet.analysis.report_verdicts`); the measured fingertip's rows and the paper's own method
  beside it as secondary tables (:mod:`flexsheet.analysis.report_analysis`).
* A segment the bag does not see end is partial and gets no verdict; a run that stopped early gets no overall
  or latency verdict (its complete segments keep theirs).
* Latency per hop, each row *modelled* (``clock: sim``: the lab's declared timings) or *measured*
  (:mod:`flexsheet.analysis.report_timing`); one delay figure, the chain's exposure → sheet at its pose.
* The tension at the contacts, with the planner's ``stiffness_scale`` and the object's unscaled stiffness.

The twin (``twin.realism``, ``twin.truth_seed``: the launch file's top-level ``twin:``, else the world node's
``twin`` param, else the world's defaults) and the scene (the launch file's top-level ``scene:``, else the
world node's ``scene`` param, else the paper's cylinder) are recorded in ``summary.json``. The metric's
object is the scene's: D is projected onto *its* surface and Δθ measured in the normal section along *its*
stroke; targets and the paper's rows belong to the paper's cylinder only.
"""

from __future__ import annotations

import json
import os
import sys
from pathlib import Path

from flexsheet.analysis.report_analysis import (
    analyse,
)
from flexsheet.analysis.report_charts import (
    compliance_chart,
    felt_chart,
    graph_chart,
    head_chart,
    latency_chart,
    table1_chart,
)
from flexsheet.analysis.report_text import CHARTS, format_text, markdown
from flexsheet.analysis.report_timing import (
    compute_vs_waiting,
    cpu_summary,
    latency_basis,
)
from flexsheet.analysis.report_verdicts import judge
from flexsheet.analysis.table1 import DD_CONVENTION
from flexsheet.calibration.display_calib_file import load_display_calib
from flexsheet.model.scenes import Scene, load_scene, paper_scene
from flexsheet.model.truth_choice import TruthChoice
from flexsheet.runtime.launch import substitute, substitutions
from flexsheet.twin import registration
from flexsheet.twin.truth import TwinTruth

__all__ = ["twin_settings", "scene_settings", "run_bags", "main", "cli"]


def twin_settings(lf=None) -> dict:
    """``{"realism", "truth_seed", "source"}`` of the twin a launch ran: the launch file's top-level ``twin``
    (a mapping or a model), else the world node's ``twin`` param, else the world's defaults (``source`` says
    which). ``lf``: the :class:`flexsheet.runtime.launch.LaunchFile` (or ``None``)."""
    def as_dict(x) -> dict | None:
        if x is None:
            return None
        if hasattr(x, "model_dump"):
            return x.model_dump()
        return dict(x) if isinstance(x, dict) else None

    twin = lf.section("twin") if lf is not None and hasattr(lf, "section") else None
    found, source = as_dict(twin), "launch file twin section"
    if found is None and lf is not None:
        for spec in getattr(lf, "nodes", {}).values():
            if getattr(spec, "type", None) == "world":
                found, source = as_dict((spec.params or {}).get("twin")), "world node params"
                break
    if found is None:
        found, source = {}, "world node defaults (the launch file names no twin)"
    tp = TruthChoice(**{k: v for k, v in found.items() if k in TruthChoice.model_fields})
    return {"realism": tp.realism, "truth_seed": tp.truth_seed, "source": source}


def scene_settings(lf=None, out: str | None = None) -> tuple[Scene, dict]:
    """The scene a launch ran and its summary entry ``{"name", "file", "kind", "description", "source"}``: the
    launch file's top-level ``scene`` (substituted; ``--set scene=FILE`` lands there), else the world node's
    ``scene`` param; without a launch file (a report again) the scene file ``out/summary.json`` names; else
    the paper's cylinder (``source`` says which). An unreadable file is reported in ``source`` and the paper's
    cylinder used (the report never fails on it)."""
    path, source = None, "the paper's cylinder (the launch file names no scene)"
    scene = lf.section("scene") if lf is not None and hasattr(lf, "section") else None
    if scene:
        path, source = os.path.expanduser(substitute(scene, substitutions(lf, out))), "launch file scene"
    elif lf is not None:
        for spec in getattr(lf, "nodes", {}).values():
            if getattr(spec, "type", None) == "world" and (spec.params or {}).get("scene"):
                path, source = str(spec.params["scene"]), "world node params"
                break
    elif out is not None:
        path, source = _reported_scene(Path(out))
    sc = paper_scene()
    if path:
        try:
            sc = load_scene(path)
        except ValueError as exc:
            source = f"{source}: unreadable ({str(exc).splitlines()[0][:200]}); the paper's cylinder used"
            path = None
    return sc, {"name": sc.name, "file": str(Path(path).resolve()) if path else None, "kind": sc.object.kind,
                "description": sc.description, "source": source}


def _reported_scene(out_dir: Path) -> tuple[str | None, str]:
    """(scene file, source) from an earlier report's ``summary.json`` in ``out_dir``; (None, the cylinder's
    source) without one, or when it names no file."""
    try:
        entry = json.loads((out_dir / "summary.json").read_text()).get("scene") or {}
    except (OSError, ValueError):
        entry = {}
    if entry.get("file"):
        return str(entry["file"]), "the scene of the run's earlier summary.json"
    return None, "the paper's cylinder (no launch file, and no earlier summary.json names a scene)"


def _clock(summary: dict, out_dir: Path) -> None:
    """``clock`` ("sim" when ``sim_clock.json`` exists, else "wall"), the sim clock's figures, and the latency
    rows' basis (:func:`~flexsheet.analysis.report_timing.latency_basis`)."""
    clock = out_dir / "sim_clock.json"
    if clock.exists():   # a clock: sim run (flexsheet.runtime.container writes it)
        sim = json.loads(clock.read_text())
        summary["clock"] = {"kind": "sim", "rtf_target": sim.get("rtf_target"),
                            "realtime_factor": sim.get("realtime_factor")}
        summary["realtime_factor"] = sim.get("realtime_factor")
        summary["readiness"] = {f"{k}_active_s": v for k, v in sim.get("active_wall_s", {}).items()}
        summary["sim_clock"] = sim
    else:
        summary["clock"] = {"kind": "wall", "rtf_target": None, "realtime_factor": 1.0}
    kind = summary["clock"]["kind"]
    summary["latency_ms"]["basis"] = latency_basis(kind)
    if kind == "wall":
        summary["latency_ms"]["compute_vs_waiting"] = compute_vs_waiting(summary, out_dir)


def sheet_model_error(summary: dict, lf=None) -> None:
    """``compliance.model_error_pct`` (and ``compliance.model_error``): the planner's identified sheet model
    against the twin's true force over the working strains
    (:func:`flexsheet.twin.registration.working_model_error`), when the run used the twin's registration of
    its truth seed (the launch's ``display_calib`` is that cached registration, or it names none); and
    ``compliance.model_error_contacts`` at the run's own contacts on the sheet
    (:func:`~flexsheet.twin.registration.contacts_model_error`). A judge's figure: it reads the truth, after
    the run."""
    tw, comp = summary.get("twin", {}), summary.get("compliance")
    if not comp or tw.get("truth_seed") is None:
        return
    path = registration.sim_display_calib_cached(int(tw["truth_seed"]), tw.get("realism", "realistic"))
    named = lf.section("display_calib") if lf is not None and hasattr(lf, "section") else None
    if named is not None and (path is None or os.path.realpath(str(named)) != os.path.realpath(path)):
        return  # the run's own display.yaml (a lab's): not the twin's registration
    sheet = load_display_calib(path).sheet if path else None
    if sheet is None:
        return
    truth = TwinTruth.draw(int(tw["truth_seed"]), tw.get("realism", "realistic"))
    err = registration.working_model_error(truth, sheet)
    comp["model_error"] = err
    comp["model_error_pct"] = err["median_pct"]
    cs = comp.get("contacts_on_sheet")           # and where this run touched the sheet
    if cs and cs.get("uv_m"):
        comp["model_error_contacts"] = registration.contacts_model_error(truth, sheet, cs["uv_m"], cs["n"])


def run_bags(out_dir: Path, since: float | None = None) -> list[Path]:
    """The bags of a run in ``out_dir``, oldest first (a respawned recorder continues in ``<stem>.N.mcap``):
    every ``*.mcap`` but replays, and with ``since`` (epoch s, the launch's start) only those written since,
    so an earlier run's bags in a reused folder are left out."""
    bags = [p for p in out_dir.glob("*.mcap") if not p.name.startswith("replay")]
    if since is not None:
        bags = [p for p in bags if p.stat().st_mtime >= since]
    return sorted(bags, key=lambda p: p.stat().st_mtime)


def main(out: str, lf=None, since: float | None = None) -> int:
    """Analyse the run's bags in ``out`` (called by ``flexsheet launch`` after the run, with ``since`` its
    start, epoch s: :func:`run_bags`) and write the report. Returns 0, or 1 without a Table I row."""
    out_dir = Path(out)
    bags = run_bags(out_dir, since)
    if not bags:
        print(f"[report] no bag in {out_dir}" + (" written by this run" if since is not None else ""),
              flush=True)
        return 1
    older = len(run_bags(out_dir)) - len(bags)
    if older:
        print(f"[report] {older} bag(s) in {out_dir} from an earlier run left out", flush=True)
    beats: list = []
    series: dict = {}
    scene, scene_entry = scene_settings(lf, out)
    summary = analyse(bags, beats, scene, series)
    summary["scene"] = scene_entry
    summary["twin"] = twin_settings(lf)
    summary["seed"] = summary["twin"].get("truth_seed")
    sheet_model_error(summary, lf)
    _clock(summary, out_dir)
    cpu = cpu_summary(out_dir)
    if cpu is not None:
        summary["cpu"] = cpu
    summary["dd_convention"] = DD_CONVENTION
    judge(summary)
    (out_dir / "summary.json").write_text(json.dumps(summary, indent=2))
    table1_chart(summary, out_dir / "table1.png")
    felt_chart(summary, series, out_dir / "felt.png")
    latency_chart(summary, out_dir / "latency.png")
    compliance_chart(summary, series, out_dir / "compliance.png")
    if summary.get("view") or summary.get("safety"):
        head_chart(summary, series, out_dir / "head.png")
    if beats:
        graph_chart(beats, out_dir / "graph.png")
    charts = [(f, cap) for f, cap in CHARTS if (out_dir / f).exists()]
    title = f"flexsheet run report: {getattr(lf, 'name', None) or out_dir.name}"
    (out_dir / "report.md").write_text(markdown(summary, title, charts))
    print(format_text(summary), flush=True)
    print(f"[report] wrote {out_dir}/summary.json, report.md, {', '.join(f for f, _ in charts)} and their "
          f"JSON (from {', '.join(b.name for b in bags)})", flush=True)
    return 0 if any(k[:1].isdigit() for k in summary) else 1


def cli(argv: list[str] | None = None) -> int:
    """``python -m flexsheet.analysis.report OUT``: the report of the run whose bags are in ``OUT`` (what
    ``flexsheet launch --out OUT`` writes after a run), written there again."""
    import argparse

    ap = argparse.ArgumentParser(prog="python -m flexsheet.analysis.report", description=cli.__doc__,
                                 epilog="example: python -m flexsheet.analysis.report out/sim")
    ap.add_argument("out", help="the run's output folder (its *.mcap bags; summary.json and charts go there)")
    return main(ap.parse_args(argv).out)


if __name__ == "__main__":
    sys.exit(cli())
