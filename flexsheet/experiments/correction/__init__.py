"""``flexsheet experiment correction``: the paper's Figs. 11 and 13 measured on the honest twin. The command
line and its description: :mod:`flexsheet.experiments.correction.cli`; one run for one truth:
:mod:`~flexsheet.experiments.correction.experiment`. The parts it runs on: the settings and the paper's
numbers (:mod:`~flexsheet.experiments.correction.settings`), the commanded poses
(:mod:`~flexsheet.experiments.correction.poses`), the estimator side
(:mod:`~flexsheet.experiments.correction.calibrated_display`,
:mod:`~flexsheet.experiments.correction.estimator`, :mod:`~flexsheet.experiments.correction.sheet_model`), the
twin side (:mod:`~flexsheet.experiments.correction.twin_world`), the measurement camera's photos
(:mod:`~flexsheet.experiments.correction.measurer`), the inclined and pushed sweeps
(:mod:`~flexsheet.experiments.correction.sweeps`), the live renderer's path
(:mod:`~flexsheet.experiments.correction.live_path`), the stability sweeps
(:mod:`~flexsheet.experiments.correction.stability`,
:mod:`~flexsheet.experiments.correction.projector_errors`), the speed timing
(:mod:`~flexsheet.experiments.correction.speed`), the figures (:mod:`~flexsheet.experiments.correction.plots`,
:mod:`~flexsheet.experiments.correction.stability_plots`) and the seeds table
(:mod:`~flexsheet.experiments.correction.seeds`)."""
