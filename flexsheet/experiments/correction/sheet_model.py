"""The renderer's pushed-sheet model for the experiment (the nominal FEM fit, as the node builds it) and its
description for the summary."""

from __future__ import annotations

from flexsheet.experiments.correction.settings import STRETCH


def _sheet_model(name: str, quick: bool = False, progress=None):
    """The renderer's pushed-sheet model (``auto``/``fem``: the nominal FEM fit, the node's
    :func:`flexsheet.rendering.state.sheet_model_for`); ``quick``: its table for centre contacts only (the experiment
    pushes at the centre; the node uses the full table)."""
    if name not in ("auto", "fem"):
        raise ValueError(f"sheet model must be 'auto' or 'fem', got {name!r}")
    from flexsheet.model.sheet_model import NominalSheetModel

    kw = {"positions": (0.0,)} if quick else {}
    return NominalSheetModel.nominal(stretch=STRETCH, progress=progress, **kw)


def _model_info(model) -> dict:
    return model.describe()
