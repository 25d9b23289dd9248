"""The world twin's physics of the display, from the hidden truth only (pure; no transport).

* **Clamps**: the true clamp pose of each arm is the *true* forward kinematics of its measured joints — the
  truth's base pose, link lengths and joint zero offsets (:meth:`flexsheet.twin.truth.TwinTruth.clamp_pose`) —
  not the bridge's model (nominal URDF at the calibrated base), whose FK the bridge publishes in
  ``ArmJointState.pose``. Under the ideal truth the two agree exactly.
* **Sheet**: the pushed sheet is the truth's sheet FEM (:mod:`flexsheet.model.sheet_fem`, its Young's modulus,
  thickness, pre-strain and grip slip) read from the shipped table family
  (:class:`flexsheet.twin.truth_sheet.TruthSheet`: modulus and thickness an exact scale of the force,
  pre-strain and slip a shift of the strain, interpolated between the family's strains), so a new truth seed
  builds nothing; the shape is the nearest family table's, mapped onto the actual span. A family with tables
  missing is an error when the world starts.

Units: m, rad; frames: display (clamps), the sheet's own (u, v) for the deflection.
"""

from __future__ import annotations

import numpy as np

from flexsheet.model import geometry
from flexsheet.model.sheet import SheetSurface, frame_from_clamps
from flexsheet.model.sheet_fem import FINGER_RADIUS
from flexsheet.model.sheet_table import FemShape
from flexsheet.twin.truth import TwinTruth
from flexsheet.twin.truth_sheet import FAMILY_DIR, SIZE, TruthSheet

__all__ = ["TruePhysics"]


class TruePhysics:
    """True clamps and true sheet of one :class:`TwinTruth` (module doc).

    ``folder``: the true sheet's table family (default the shipped one); ``size`` m: the unstretched sheet
    side between the clamps; ``half_width`` m: half the sheet's width (both the family's: 0.24 m, 0.12 m).
    Raises ``ValueError`` for another size, ``FileNotFoundError`` for a family that lacks tables.
    """

    def __init__(self, truth: TwinTruth, folder: str = FAMILY_DIR, size: float = geometry.SHEET_SIZE,
                 half_width: float = geometry.SHEET_SIZE / 2) -> None:
        if abs(size - SIZE) > 1e-9 or abs(half_width - SIZE / 2) > 1e-9:
            raise ValueError(f"the true sheet's table family is of the {SIZE} m sheet, got size {size!r}, "
                             f"half width {half_width!r}")
        self.truth = truth
        self.size = float(size)
        self.half_width = float(half_width)
        self.sheet = TruthSheet.of(truth, folder)

    # ------------------------------------------------------------------------------------------- clamps
    def clamp_pose(self, side: str, q) -> np.ndarray:
        """True T_display_clamp (4, 4) of arm ``side`` at the measured joints ``q`` (6,) rad."""
        return self.truth.clamp_pose(side, q)

    # -------------------------------------------------------------------------------------------- sheet
    def shape(self, depth: float, push_u: float, push_v: float, half_span: float) -> FemShape:
        """The true pushed shape at the measured span ``half_span`` (m): force and stiffness of the truth's
        sheet at that clamp strain, the deflection of the nearest family table. Raises ``ValueError`` for a
        contact outside the sheet."""
        stretch = 2.0 * half_span / self.size - 1.0
        return self.sheet.shape(depth, push_u, push_v, half_span, stretch)

    def surface(self, T_left: np.ndarray, T_right: np.ndarray, finger: np.ndarray | None
                ) -> tuple[SheetSurface, float]:
        """The true sheet held by the true clamp poses (4, 4), pushed by the fingertip ``finger`` (3,) m when
        it is behind the sheet plane and inside it. Returns (surface, clamp strain, signed: negative when
        slack). The surface's ``membrane`` is a :class:`FemShape` (or ``None``: flat). Raises ``ValueError``
        for clamps that hold no sheet (see :func:`flexsheet.model.sheet.frame_from_clamps`)."""
        origin, n, eu, a = frame_from_clamps(T_left, T_right)
        stretch = 2.0 * a / self.size - 1.0
        mem = None
        if finger is not None:
            d = np.asarray(finger, float) - origin
            depth = -float(d @ n)
            pu, pv = float(d @ eu), float(d @ np.cross(n, eu))
            if depth > 0.0 and abs(pu) < a - FINGER_RADIUS and abs(pv) <= self.half_width:
                mem = self.shape(depth, pu, pv, a)
        return SheetSurface(origin, n, eu, a, self.half_width, mem, self.size), stretch

