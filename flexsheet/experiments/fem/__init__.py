"""``flexsheet experiment fem``: the physically right deformation of the pushed cylinder (the hyperelastic
reference) and the real-time model that reproduces it. The command line and what it writes:
:mod:`flexsheet.experiments.fem.cli`; the runs: :mod:`~flexsheet.experiments.fem.runs`; the studies, one
family a module: :mod:`~flexsheet.experiments.fem.studies`; the candidates judged against the reference:
:mod:`~flexsheet.experiments.fem.candidates`; the outputs and figures: :mod:`~flexsheet.experiments.fem.outputs`,
:mod:`~flexsheet.experiments.fem.plots`; the pushes a run reads: :mod:`~flexsheet.experiments.fem.plan`. The
library parts it runs on: the settings and the cached reference pushes (:mod:`flexsheet.fem.reference_settings`,
:mod:`flexsheet.fem.reference_paths`, :mod:`flexsheet.fem.visible_error`), the worker processes
(:mod:`flexsheet.fem.workers`) and the node's table (:mod:`flexsheet.fem.node_table`). The names below are
re-exported for the registry (``flexsheet.experiments.fem:main``), the scene tables and the tests."""

from flexsheet.experiments.fem.candidates import (
    candidates,
    snapshot_mesh_study,
    snapshot_source,
    update_ms,
    validation_set,
)
from flexsheet.experiments.fem.cli import main
from flexsheet.experiments.fem.outputs import failure_map, model_table, summary
from flexsheet.experiments.fem.plan import planned_solves
from flexsheet.experiments.fem.plots import plot_node_table
from flexsheet.experiments.fem.studies.convergence import convergence, penalty_study, skin_study
from flexsheet.experiments.fem.studies.fold import fold_study
from flexsheet.experiments.fem.studies.fold_check import fold_path
from flexsheet.experiments.fem.studies.holdout import holdout_grid, holdout_study
from flexsheet.experiments.fem.studies.linear import linear_study
from flexsheet.experiments.fem.studies.material import material_study
from flexsheet.experiments.fem.studies.mirror import (
    mirror_asymmetry,
    mirror_blocks,
    mirror_stability,
    mirror_study,
)
from flexsheet.experiments.fem.studies.tip import _tip_verdict, tip_sequence, tip_specs
from flexsheet.fem.hyperelastic import DEFAULT_CONTACT, PENALTY_SCALE, PREVIOUS_VERSION, SOLVER_VERSION
from flexsheet.fem.node_table import (
    TWIN_DR,
    _table_update_ms,
    build_node_table,
    node_table_between_depths,
    node_table_compare,
    node_table_holdout,
    node_table_path,
    node_table_report,
    twin_spec,
)
from flexsheet.fem.reference_paths import _depths, _ref_model, _reference_keys, reference_path, stable_path
from flexsheet.fem.reference_settings import FINGER_R, NEWTON_ITERS, TARGET, Settings, settings_for
from flexsheet.fem.snapshots import DEFAULT_GRID, DEFAULT_REF_SPEC
from flexsheet.fem.visible_error import errors, realtime_model
from flexsheet.fem.workers import Solve, default_jobs, missing_solves, prefetch, run_workers

__all__ = [
    "DEFAULT_CONTACT", "DEFAULT_GRID", "DEFAULT_REF_SPEC", "FINGER_R", "NEWTON_ITERS", "PENALTY_SCALE",
    "PREVIOUS_VERSION", "SOLVER_VERSION", "TARGET", "TWIN_DR", "Settings", "Solve", "_depths", "_ref_model",
    "_reference_keys", "_table_update_ms", "_tip_verdict", "build_node_table", "candidates", "convergence",
    "default_jobs", "errors", "failure_map", "fold_path", "fold_study", "holdout_grid", "holdout_study",
    "linear_study", "main", "material_study", "mirror_asymmetry", "mirror_blocks", "mirror_stability", "mirror_study",
    "missing_solves", "model_table", "node_table_between_depths", "node_table_compare", "node_table_holdout",
    "node_table_path", "node_table_report", "penalty_study", "planned_solves", "plot_node_table", "prefetch",
    "realtime_model", "reference_path", "run_workers", "settings_for", "skin_study", "snapshot_mesh_study",
    "snapshot_source", "stable_path", "summary", "tip_sequence", "tip_specs", "twin_spec", "update_ms",
    "validation_set",
]
