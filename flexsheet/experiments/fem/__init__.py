"""``flexsheet experiment fem``: the physically right deformation of the pushed cylinder (the hyperelastic
reference) and the real-time model that reproduces it. The command line and what it writes:
:mod:`flexsheet.experiments.fem.cli`; the runs: :mod:`~flexsheet.experiments.fem.runs`; the studies, one
family a module: :mod:`~flexsheet.experiments.fem.studies`; the candidates judged against the reference:
:mod:`~flexsheet.experiments.fem.candidates`; the outputs and figures:
:mod:`~flexsheet.experiments.fem.outputs`, :mod:`~flexsheet.experiments.fem.plots`; the pushes a run reads:
:mod:`~flexsheet.experiments.fem.plan`. The library parts it runs on: the settings and the cached reference
pushes (:mod:`flexsheet.fem.reference.settings`, :mod:`flexsheet.fem.reference.paths`,
:mod:`flexsheet.fem.visible_error`), the worker processes (:mod:`flexsheet.fem.reference.workers`) and the
node's table (:mod:`flexsheet.fem.reference.node_table`). The command's entry point is
:func:`flexsheet.experiments.fem.cli.main`."""
