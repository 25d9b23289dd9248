"""What the estimators may know about the display (:class:`CalibratedDisplay`) and where it comes from for a
truth seed (:func:`display_calib_for`: a ``display.yaml``, or the registration procedures run in the twin)."""

from __future__ import annotations

import json
import logging
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from flexsheet.calibration.display_calib import DisplayCalib, nominal_display_calib
from flexsheet.calibration.display_calib_file import load_display_calib
from flexsheet.model.projector import Projector
from flexsheet.twin.registration import sim_display_calib

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class CalibratedDisplay:
    """Everything the estimators may know about the display: ``projector`` (calibrated K_p and pose),
    ``distortion`` (5,) its OpenCV distortion, ``eye`` (3,) m V, ``ipd`` m, ``bases`` side → T_display_base
    (4, 4) of the calibrated arms, ``source`` (where it came from: a ``display.yaml`` path or ``nominal``),
    ``strain_offset``: the sheet's identified strain offset ε₀ (its ``sheet`` entry; 0 without one)."""

    projector: Projector
    distortion: np.ndarray
    eye: np.ndarray
    ipd: float
    bases: dict
    source: str
    strain_offset: float = 0.0

    @classmethod
    def from_display_calib(cls, dc: DisplayCalib, source: str = "") -> CalibratedDisplay:
        """From a ``display.yaml`` (:class:`DisplayCalib`); raises ``ValueError`` naming missing entries."""
        if not isinstance(dc, DisplayCalib):
            raise TypeError(f"from_display_calib takes a DisplayCalib, got {type(dc).__name__}")
        dc.require("projector", "eye", "arms.left", "arms.right")
        p = dc.projector
        return cls(p.projector(), np.asarray(p.D, float).ravel().copy(), np.asarray(dc.eye.V, float).copy(),
                   float(dc.eye.ipd),
                   {s: np.asarray(dc.arms[s].T_display_base, float).copy() for s in ("left", "right")},
                   source or dc.path or "display calibration",
                   0.0 if dc.sheet is None else float(dc.sheet.strain_offset))

    @classmethod
    def nominal(cls) -> CalibratedDisplay:
        """The nominal display (code constants; nothing measured)."""
        return cls.from_display_calib(nominal_display_calib(), "nominal")



def display_calib_for(seed: int, realism: str, path: str | None = None,
                      quick: bool = False) -> tuple[CalibratedDisplay, dict]:
    """The estimator's display for truth ``seed``: ``path`` (a display.yaml) if given, else the registration
    procedures run in the twin (:func:`flexsheet.twin.registration.sim_display_calib`, cached per seed;
    ``quick``: its quick preset). Returns (display, info with the path and, when known, the registration's own
    errors against the truth from its summary.json)."""
    if path is None:
        path = sim_display_calib(int(seed), realism, quick=quick)
    cal = CalibratedDisplay.from_display_calib(load_display_calib(path), path)
    info: dict = {"display_calib": path}
    sj = Path(path).with_name("summary.json")
    if sj.is_file():
        try:
            s = json.loads(sj.read_text())
            info["registration_errors"] = {k: s[k] for k in ("camera", "projector", "arms") if k in s}
        except (OSError, ValueError):
            pass
    return cal, info
