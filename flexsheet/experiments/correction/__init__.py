"""``flexsheet experiment correction``: the paper's Figs. 11 and 13 measured on the honest twin. The command
line and its description: :mod:`flexsheet.experiments.correction.cli`; one run for one truth:
:mod:`~flexsheet.experiments.correction.experiment`. The parts it runs on: the settings and the paper's numbers
(:mod:`~flexsheet.experiments.correction.settings`), the commanded poses
(:mod:`~flexsheet.experiments.correction.poses`), the estimator side
(:mod:`~flexsheet.experiments.correction.calibrated_display`, :mod:`~flexsheet.experiments.correction.estimator`,
:mod:`~flexsheet.experiments.correction.sheet_model`), the twin side
(:mod:`~flexsheet.experiments.correction.twin_world`), the measurement camera's photos
(:mod:`~flexsheet.experiments.correction.measurer`), the inclined and pushed sweeps
(:mod:`~flexsheet.experiments.correction.sweeps`), the live renderer's path
(:mod:`~flexsheet.experiments.correction.live_path`), the stability sweeps
(:mod:`~flexsheet.experiments.correction.stability`, :mod:`~flexsheet.experiments.correction.projector_errors`),
the speed timing (:mod:`~flexsheet.experiments.correction.speed`), the figures
(:mod:`~flexsheet.experiments.correction.plots`, :mod:`~flexsheet.experiments.correction.stability_plots`) and
the seeds table (:mod:`~flexsheet.experiments.correction.seeds`). The names below are re-exported for the
registry (``flexsheet.experiments.correction:main``) and the tests."""

from flexsheet.experiments.correction.calibrated_display import CalibratedDisplay, display_calib_for
from flexsheet.experiments.correction.cli import main
from flexsheet.experiments.correction.estimator import DisplayEstimator
from flexsheet.experiments.correction.experiment import run
from flexsheet.experiments.correction.live_path import LivePath, live_path
from flexsheet.experiments.correction.measurer import Measurer
from flexsheet.experiments.correction.poses import HOME_POSE, inclined_pose
from flexsheet.experiments.correction.projector_errors import (
    PROJECTOR_SCALES,
    PROJECTOR_UNIT_ERROR,
    RANDOM_SCALES,
    mapping_error_px,
    perturbed_projector,
    scaled_error,
    sweep_projector,
)
from flexsheet.experiments.correction.seeds import aggregate
from flexsheet.experiments.correction.settings import (
    ASSUMPTIONS,
    FEM_DEPTHS,
    FEM_POSITIONS,
    MODEL_LABELS,
    PAPER,
    PIXEL,
    STRETCH,
)
from flexsheet.experiments.correction.sheet_model import _sheet_model
from flexsheet.experiments.correction.speed import model_speed
from flexsheet.experiments.correction.stability import (
    PRESTRAINS,
    TENSION_FACTORS,
    breaking_point,
    sweep_sheet,
)
from flexsheet.experiments.correction.sweeps import (
    measure_inclined,
    measure_pushed,
    sweep_inclined,
    sweep_pushed,
)
from flexsheet.experiments.correction.twin_world import TwinWorld

__all__ = ["main", "run", "inclined_pose", "CalibratedDisplay", "DisplayEstimator", "TwinWorld", "Measurer",
           "PIXEL", "STRETCH", "PAPER", "sweep_sheet", "sweep_projector", "breaking_point",
           "scaled_error", "mapping_error_px", "perturbed_projector",
           "ASSUMPTIONS", "FEM_DEPTHS", "FEM_POSITIONS", "HOME_POSE", "LivePath", "MODEL_LABELS", "PRESTRAINS",
           "PROJECTOR_SCALES", "PROJECTOR_UNIT_ERROR", "RANDOM_SCALES", "TENSION_FACTORS", "_sheet_model",
           "aggregate", "display_calib_for", "live_path", "measure_inclined", "measure_pushed", "model_speed",
           "sweep_inclined", "sweep_pushed"]
