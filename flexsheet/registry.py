"""Where the CLI finds experiments, benchmarks and calibration commands (node types are entry points of the
``flexsheet.nodes`` group: :mod:`flexsheet.runtime.plugins`).

Each entry is ``"module:attribute"`` and is imported lazily, so ``flexsheet --help`` stays fast and a
broken optional module only breaks its own subcommand. Experiment, bench and calibrate entries name a
``main(argv: list[str]) -> int`` function that parses its own arguments with argparse (its ``--help`` shows a
working example). All three are entry points (pyproject.toml): :data:`EXPERIMENTS_GROUP`,
:data:`CALIBRATE_GROUP` and :data:`BENCHES_GROUP` (the library's and the nodes' own benches alike).
"""

from __future__ import annotations

import importlib
from typing import Any

from flexsheet.runtime.plugins import table

#: the entry-point group of ``flexsheet bench NAME``
BENCHES_GROUP = "flexsheet.benches"

#: the entry-point group of ``flexsheet experiment NAME``
EXPERIMENTS_GROUP = "flexsheet.experiments"
#: the entry-point group of ``flexsheet calibrate NAME``
CALIBRATE_GROUP = "flexsheet.calibrate"


def experiments() -> dict[str, str]:
    """Experiment name → ``"module:main"``: the entry points of :data:`EXPERIMENTS_GROUP`, sorted by name."""
    return table(EXPERIMENTS_GROUP)


def calibrations() -> dict[str, str]:
    """Calibration name → ``"module:main"``: the entry points of :data:`CALIBRATE_GROUP`, sorted by name."""
    return table(CALIBRATE_GROUP)


def benches() -> dict[str, str]:
    """Bench name → ``"module:main"``: the entry points of :data:`BENCHES_GROUP`, sorted by name."""
    return table(BENCHES_GROUP)


def load(spec: str) -> Any:
    """Import ``"module:attribute"`` and return the attribute; raises ``ImportError``/``AttributeError``."""
    module, _, attr = spec.partition(":")
    return getattr(importlib.import_module(module), attr)
