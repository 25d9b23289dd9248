"""Where the CLI finds experiments, benchmarks and calibration commands (node types are entry points of the
``flexsheet.nodes`` group: :mod:`flexsheet.runtime.plugins`).

Each entry is ``"module:attribute"`` and is imported lazily, so ``flexsheet --help`` stays fast and a
broken optional module only breaks its own subcommand. Experiment, bench and calibrate entries name a
``main(argv: list[str]) -> int`` function that parses its own arguments with argparse (its ``--help`` shows a
working example). The benches are entry points of the :data:`BENCHES_GROUP` group (pyproject.toml), the
library's and the nodes' own alike.
"""

from __future__ import annotations

import importlib
from typing import Any

from flexsheet.runtime.plugins import table

#: the entry-point group of ``flexsheet bench NAME``
BENCHES_GROUP = "flexsheet.benches"

EXPERIMENTS: dict[str, str] = {
    "triangulation": "flexsheet.experiments.triangulation:main",
    "stroke": "flexsheet.experiments.stroke:main",
    "stroke_model": "flexsheet.experiments.stroke_model:main",
    "scenes": "flexsheet.experiments.scenes:main",
    "fem": "flexsheet.experiments.fem.cli:main",
    "correction": "flexsheet.experiments.correction.cli:main",
    "stability": "flexsheet.experiments.stability:main",
    "compliance": "flexsheet.experiments.compliance:main",
    "latency_load": "flexsheet.experiments.latency_load:main",
    "determinism": "flexsheet.experiments.determinism:main",
    "faults": "flexsheet.experiments.faults.experiment:main",
}

CALIBRATE: dict[str, str] = {
    "stereo": "flexsheet.vision.stereo_calibration:main",
    "camera-pose": "flexsheet.display.calibrate:camera_pose_main",
    "projector": "flexsheet.display.calibrate:projector_main",
    "arms": "flexsheet.display.calibrate:arms_main",
    "eye": "flexsheet.display.calibrate:eye_main",
    "sheet": "flexsheet.display.calibrate:sheet_main",
    "display": "flexsheet.display.calibrate:display_main",
    "noise": "flexsheet.display.calibrate:noise_main",
}


def benches() -> dict[str, str]:
    """Bench name → ``"module:main"``: the entry points of :data:`BENCHES_GROUP`, sorted by name."""
    return table(BENCHES_GROUP)


def load(spec: str) -> Any:
    """Import ``"module:attribute"`` and return the attribute; raises ``ImportError``/``AttributeError``."""
    module, _, attr = spec.partition(":")
    return getattr(importlib.import_module(module), attr)
