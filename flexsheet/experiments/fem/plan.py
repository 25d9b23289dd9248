"""Every reference push a run reads (:func:`planned_solves`), for
:func:`flexsheet.fem.reference.workers.prefetch` to solve in worker processes before the run reads them from
the cache."""

from __future__ import annotations

from dataclasses import replace

from flexsheet.experiments.fem.studies.holdout import holdout_grid
from flexsheet.experiments.fem.studies.tip import tip_specs
from flexsheet.fem.reference.settings import Settings
from flexsheet.fem.reference.workers import Solve


def planned_solves(st: Settings, study: str = "full") -> list[Solve]:
    """Every reference path :func:`main`'s run reads (``study``: "full", or the "mirror" / "holdout" / "fold"
    / "material" study alone, ``--mirror-study`` / ``--holdout-study`` / ``--fold-study`` /
    ``--material-study``, the last per material), once each (as :func:`reference_path` keys them), most
    expensive first. Keep it in step with the functions that read them: :func:`convergence`,
    :func:`mirror_study` (its stability check reads the last two levels), :func:`penalty_study`,
    :func:`skin_study`, :func:`validation_set`, :func:`snapshot_source`, :func:`snapshot_mesh_study` (the skin
    study's meshes) and :func:`holdout_study`; a path may be listed twice. A run after :func:`prefetch` of
    this list solves nothing itself (tests/unit/experiments/fem/test_runs.py checks the quick run's log).
    ``ValueError`` on another ``study``."""
    if study not in ("full", "mirror", "holdout", "fold", "material"):
        raise ValueError(f"study must be 'full', 'mirror', 'holdout', 'fold' or 'material', got {study!r}")
    lv = st.levels
    if study == "material":  # material_study, per material: the levels and the table's stable branch
        jobs = [Solve(s, 0.0, st.depth_step) for s in lv[:-1]] + [Solve(lv[-1], 0.0, st.fine_step)]
        jobs.append(Solve(lv[-2], 0.0, st.depth_step, stable=True))
        chk = tip_specs(st)[1]
        jobs += [Solve(chk, 0.0, st.depth_step)] if chk is not None else []
        return sorted(jobs, key=lambda j: -j.cost())
    if study == "fold":                  # fold_study: the last three levels, the tip sequence and its check
        seq, chk = tip_specs(st)
        jobs = [Solve(s, 0.0, st.depth_step) for s in lv[-3:-1]] + [Solve(lv[-1], 0.0, st.fine_step)]
        jobs += [Solve(s, 0.0, st.depth_step) for s in seq + ([chk] if chk is not None else [])]
        jobs += [Solve(s, 0.0, st.depth_step, stable=True) for s in (lv[-2], seq[-2])]     # _tip_snapshots
        return sorted(jobs, key=lambda j: -j.cost())

    def snapshot_jobs(s: Settings) -> list[Solve]:      # validation_set's held-out paths, snapshot_source's
        jobs = [Solve(s.snap_spec, a, s.fine_step, stable=True) for a in s.holdout_deg]
        jobs += [Solve(s.snap_spec, a, s.fine_step, stable=True) for a in s.grid.angles_deg if a != 0.0]
        jobs.append(Solve(s.snap_spec, 0.0, s.fine_step if s.snap_spec == lv[-1] else s.depth_step,
                          stable=True))
        return jobs

    if study == "holdout":
        jobs = [Solve(lv[-1], 0.0, st.fine_step)] + snapshot_jobs(holdout_grid(st))
        return sorted(jobs, key=lambda j: -j.cost())
    jobs = [Solve(s, 0.0, st.depth_step) for s in lv[:-1]] + [Solve(lv[-1], 0.0, st.fine_step)]
    jobs += [Solve(replace(lv[-1], h_fine=hf, half_z=False, cut=True), 0.0, st.fine_step)
             for hf in st.half_levels]
    if study == "full":
        jobs += [Solve(lv[st.penalty_level], 0.0, st.depth_step, sc) for sc in st.penalty_scales]
        # the skin study's paths, read as their stable branch by snapshot_mesh_study's tables (its base mesh:
        # the snapshot mesh in full mode, a job of its own in quick mode)
        jobs += [Solve(replace(lv[-2], skin_h=h), 0.0, st.depth_step, stable=True) for h in st.skin_sizes]
        jobs.append(Solve(lv[-2], 0.0, st.depth_step, stable=True))
        jobs += snapshot_jobs(st)
    return sorted(jobs, key=lambda j: -j.cost())      # repeats are dropped by prefetch (by cache key)
