"""The renderer's pushed-sheet model for the experiment (the gripped sheet's FEM depth table with the
identified strain offset, as the node builds it) and its description for the summary."""

from __future__ import annotations

import logging

from flexsheet.experiments.correction.settings import STRETCH
from flexsheet.model.sheet_model import NominalSheetModel

log = logging.getLogger(__name__)


def pushed_sheet_model(name: str, quick: bool = False, strain_offset: float = 0.0):
    """The renderer's pushed-sheet model (``auto``/``fem``: the gripped sheet's FEM depth table, the node's
    :func:`flexsheet.model.sheet_model.sheet_model_for`) with the identified ``strain_offset``
    (``display.yaml``'s sheet entry); ``quick``: its tables for centre contacts only (the experiment pushes at
    the centre; the node uses the full tables)."""
    if name not in ("auto", "fem"):
        raise ValueError(f"sheet model must be 'auto' or 'fem', got {name!r}")

    kw = {"positions": (0.0,)} if quick else {}
    return NominalSheetModel.nominal(stretch=STRETCH, strain_offset=strain_offset, **kw)


def sheet_model_info(model) -> dict:
    """What the summary records of the pushed-sheet ``model`` (its ``describe()``)."""
    return model.describe()
