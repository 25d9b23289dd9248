"""The runs of ``flexsheet experiment fem`` on the paper's cylinder (:func:`run`), after the command line is
checked (:mod:`flexsheet.experiments.fem.cli`): one convergence level (``--level``), a study alone
(``--material-study``, ``--holdout-study``, ``--fold-study``, ``--mirror-study``), or the full run (the
convergence, penalty, skin and mirror studies, the snapshot table, the candidates and the outputs)."""

from __future__ import annotations

import json
import logging
import time
from dataclasses import replace

from flexsheet.experiments.fem.candidates import (
    candidates,
    snapshot_mesh_study,
    snapshot_source,
    validation_set,
)
from flexsheet.experiments.fem.outputs import failure_map, model_table, summary, write_json
from flexsheet.experiments.fem.plan import planned_solves
from flexsheet.experiments.fem.plots import (
    plot_candidates,
    plot_convergence,
    plot_fold_study,
    plot_holdout_study,
    plot_material_study,
    plot_mirror_study,
)
from flexsheet.experiments.fem.studies.convergence import convergence, penalty_study, skin_study
from flexsheet.experiments.fem.studies.fold import fold_study
from flexsheet.experiments.fem.studies.holdout import holdout_study
from flexsheet.experiments.fem.studies.linear import linear_study
from flexsheet.experiments.fem.studies.material import material_study
from flexsheet.experiments.fem.studies.mirror import mirror_study
from flexsheet.fem.cache import ArrayCache
from flexsheet.fem.choose import MODEL_TABLE_PATH
from flexsheet.fem.material import Material
from flexsheet.fem.realtime import RealtimeModel
from flexsheet.fem.reference.capsule_contact import DEFAULT_CONTACT, PENALTY_SCALE
from flexsheet.fem.reference.paths import push_depths, reference_path, snapshot_table
from flexsheet.fem.reference.settings import DEFAULT_MATERIAL, PENALTY_TOL_MM, Settings, law_name
from flexsheet.fem.reference.workers import prefetch
from flexsheet.fem.visible_error import realtime_model
from flexsheet.model.scene_parts import GENT_JM_RUBBER

log = logging.getLogger(__name__)


def run(args, st: Settings, mat: Material, cache: ArrayCache, t0: float) -> int:
    """The run ``args`` (:func:`flexsheet.experiments.fem.cli.main`'s, checked) asks for with settings ``st``
    and material ``mat``, started at ``t0`` (``time.perf_counter``); returns 0."""
    for h in st.skin_sizes:  # before any solve: a bad size would otherwise fail after the convergence study
        replace(st.levels[-2], skin_h=h)
    rm = realtime_model(st, mat, args.cache_dir or None)
    probes = rm.rest_vertices.astype(float)       # the rendered vertices every reference path is sampled at
    if args.level is not None:
        if not 0 <= args.level < len(st.levels):
            raise SystemExit(f"--level must be in [0, {len(st.levels) - 1}], got {args.level}")
        last = args.level == len(st.levels) - 1
        reference_path(st.levels[args.level], 0.0, push_depths(st.fine_step if last else st.depth_step), mat,
                       cache,
                       probes, st.contact)
        log.info(f"level {args.level} cached in {time.perf_counter() - t0:.1f} s")
        return 0
    if args.material_study:
        mats = (Material(mat.E, mat.nu), Material(mat.E, mat.nu, mat.Jm if mat.gent else GENT_JM_RUBBER))
        for m in mats:
            prefetch(planned_solves(st, "material"), args.jobs, m, cache, probes, st.contact)
        return _study_done(args.out, "material_study", material_study(st, mats, cache, rm),
                           plot_material_study, t0)
    study = "mirror" if args.mirror_study else "holdout" if args.holdout_study else \
        "fold" if args.fold_study else "full"
    prefetch(planned_solves(st, study), args.jobs, mat, cache, probes, st.contact)
    if args.holdout_study:
        fine = reference_path(st.levels[-1], 0.0, push_depths(st.fine_step), mat, cache, probes, st.contact)
        return _study_done(args.out, "holdout_study", holdout_study(st, mat, cache, rm, fine),
                           plot_holdout_study, t0)
    if args.fold_study:
        return _study_done(args.out, "fold_study", fold_study(st, mat, cache, rm), plot_fold_study, t0)
    conv, fine = convergence(st, mat, cache, rm)
    if args.mirror_study:
        return _study_done(args.out, "mirror_study", mirror_study(st, mat, cache, rm, conv, fine),
                           plot_mirror_study,
                           t0)
    return _full_run(args, st, mat, cache, rm, conv, fine, t0)


def _study_done(out: str, name: str, result: dict, plot, t0: float) -> int:
    """Write a study run alone: ``name``.json and its figure (``plot``) into ``out``, and log it; returns
    0."""
    write_json(out, name, result)
    plot(out, result)
    log.info(f"{name.replace('_', ' ')} done in {time.perf_counter() - t0:.1f} s -> {out}/{name}.json")
    return 0


def _full_run(args, st: Settings, mat: Material, cache: ArrayCache, rm: RealtimeModel, conv: dict, fine: dict,
              t0: float) -> int:
    """The full (or ``--quick``) run after :func:`convergence`: the penalty, skin and mirror studies, the
    snapshot table, the candidates judged on the validation set, and every output; returns 0."""
    _penalty_and_skin(st, mat, cache, rm, conv, fine)
    ms = mirror_study(st, mat, cache, rm, conv, fine)
    solved, src = snapshot_source(st, mat, cache, rm, fine)
    table, hit, sec = snapshot_table(st, mat, cache, solved)
    sec += float(src["seconds"])              # the solve the table was sampled from
    rm.attach_snapshots(table)
    snap_info = {"snapshot_azimuths_deg": list(st.grid.angles_deg),
                 "snapshot_depth_step_mm": st.grid.depth_step * 1e3,
                 "snapshot_mesh": st.snap_spec.__dict__, "precompute_s": sec, "precompute_cache_hit": hit,
                 "table_MB": rm.snapshots.nbytes / 1e6}
    cases = validation_set(st, mat, cache, rm, fine)
    cand = candidates(st, mat, rm, table, cases)
    snap_info["snapshot_mesh_study"] = snapshot_mesh_study(st, mat, cache, rm, cases)
    fmap = failure_map(cases, cand)
    summ = summary(st, conv, cand, cases, snap_info, mat, time.perf_counter() - t0)
    _write_full(args, st, mat, conv, ms, cand, cases, fmap, summ)
    log.info(json.dumps(summ["realtime"], indent=1))
    log.info(f"done in {time.perf_counter() - t0:.1f} s -> {args.out}")
    return 0


def _penalty_and_skin(st: Settings, mat: Material, cache: ArrayCache, rm: RealtimeModel, conv: dict,
                      fine: dict) -> None:
    """Add the penalty study (and its verdict to ``conv``'s) and the skin study to :func:`convergence`'s
    report ``conv``."""
    pen = penalty_study(st, mat, cache, rm)
    conv["penalty_study"] = pen
    conv["mesh_converged"] = conv["converged"]
    conv["converged"] = conv["converged"] and pen["converged"]
    conv["criterion"] += (f"; and the contact penalty converged: the default {PENALTY_SCALE:g}·E/h within "
                          f"{PENALTY_TOL_MM:g} mm of a 10x stiffer one (penalty_study)")
    conv["skin_study"] = skin_study(st, mat, cache, rm, conv, fine)


def _write_full(args, st: Settings, mat: Material, conv: dict, ms: dict, cand: dict, cases: list[dict],
                fmap: dict, summ: dict) -> None:
    """The full run's JSON files and figures into ``args.out``, the node's model table where it is due, and
    the linear study when asked for."""
    write_json(args.out, "convergence", conv)
    write_json(args.out, "mirror_study", ms)
    write_json(args.out, "failure_map", fmap)
    write_json(args.out, "accuracy_speed", {k: {"name": v["name"], "update_ms": v["time_ms"],
                                                "max_visible_error_mm_0_50": max(v["errors_m"]) * 1e3}
                                            for k, v in cand.items()})
    write_json(args.out, "summary", summ)
    # the node's model table: a full run of the default scene's material and contact law (or asked for)
    if (not st.quick and st.contact == DEFAULT_CONTACT and mat == DEFAULT_MATERIAL) \
            or args.write_model_table:
        with open(MODEL_TABLE_PATH, "w") as fh:
            json.dump(model_table(cases, cand, law_name(mat)), fh, indent=1)
    plot_convergence(args.out, conv, law_name(mat))
    plot_mirror_study(args.out, ms)
    plot_candidates(args.out, cand, fmap, law_name(mat))
    if args.linear_study:
        linear_study(args.out, mat)
