"""The joint speeds and accelerations the sheet's motion asks of the two arms (:class:`JointRates`), which the
planner's :class:`~flexsheet.arm.sheet_motion.SheetShaper` slows a segment for. Units: rad, rad/s, rad/s²."""

from __future__ import annotations

import numpy as np

from flexsheet.arm.kinematics import ArmKinematics
from flexsheet.arm.sheet_motion import SheetSegment

__all__ = ["JointRates"]


class JointRates:
    """The joint speeds and accelerations a segment asks of the two arms, relative to the bridges' limits.

    ``bases``: {"left", "right"}: (x, y, z, yaw) or (4, 4) T_display_base (the registered ones); ``qd_max``
    and ``qdd_max`` (6,) rad/s and rad/s²: the bridges' limits (the URDF's × ``speed_scale``, ×
    ``accel_scale``). Joint rates are mapped from the clamps' twists, at ``samples`` instants, through the
    Jacobians at the arms' joints for the segment's goal and start and at each instant's own joints (one
    Newton step along the segment from the start's): near the wrist's singularity the Jacobian turns within
    one segment, and the ends alone missed peaks of 1.8× the limit on a drawn ellipsoid. ``accel_allowance``:
    how far past ``qdd_max`` a segment's peak joint acceleration may go (:meth:`ratios`)."""

    def __init__(self, bases: dict, qd_max, qdd_max, samples: int = 4, accel_allowance: float = 1.0) -> None:
        if set(bases) != {"left", "right"}:
            raise ValueError(f"bases must name 'left' and 'right', got {sorted(bases)}")
        self.kin = {s: ArmKinematics(s, b) for s, b in bases.items()}
        self.qd_max = np.asarray(qd_max, float)
        self.qdd_max = np.asarray(qdd_max, float)
        if (self.qd_max.shape != (6,) or self.qdd_max.shape != (6,) or (self.qd_max <= 0).any()
            or (self.qdd_max <= 0).any()):
            raise ValueError(f"qd_max and qdd_max must be positive (6,) vectors, got {qd_max!r}, {qdd_max!r}")
        self.samples = int(samples)
        if not accel_allowance >= 1.0:
            raise ValueError(f"accel_allowance must be >= 1, got {accel_allowance!r}")
        self.accel_allowance = float(accel_allowance)
        self._jinv: dict[str, np.ndarray] = {}     # side: (n, 6, 6) inverse Jacobians
        self._seed: dict[str, np.ndarray] = {}     # side: the joints (6,) rad the segment starts near

    def at(self, joints: dict) -> None:
        """The arms' joints (6,) rad to map through: {side: [q, ...]} (e.g. the IK of this plan's targets and
        of the last plan's). A singular Jacobian is skipped. The last of each side's list also seeds
        :meth:`ratios`' joints along the segment."""
        self._jinv = {}
        self._seed = {side: np.asarray(qs[-1], float) for side, qs in joints.items() if len(qs)}
        for side, qs in joints.items():
            out = []
            for q in qs:
                try:
                    out.append(np.linalg.inv(self.kin[side].jacobian(q)))
                except np.linalg.LinAlgError:
                    pass
            self._jinv[side] = np.asarray(out).reshape(-1, 6, 6)

    def ratios(self, seg: SheetSegment) -> tuple[float, float]:
        """(peak joint speed / ``qd_max``, peak joint acceleration / (``accel_allowance`` × ``qdd_max``)) over
        both arms and the sampled instants of ``seg``. An allowance over 1 lets accelerations past the
        bridges' limit through, which their limiters then do not follow: the clamps leave the motion (the
        organ, limit 2× speed, allowance 3: 30 mm, span 5.3 mm p99). The default 1 with the bridges' limit at
        6× speed gives the motion the same accelerations, and the limiters follow them
        (``tests/unit/arm/test_sheet_motion.py``)."""
        sides = [s for s, j in self._jinv.items() if len(j)]
        if seg.duration <= 0.0 or not sides:
            return 0.0, 0.0
        rv = ra = 0.0
        q = {s: self._seed[s] for s in sides if s in self._seed}
        for k in range(self.samples):
            clamps = seg.clamps(seg.t0 + seg.duration * (k + 0.5) / self.samples, True, sides)
            for side, (T, tw, dtw) in zip(sides, clamps, strict=True):
                Ji = self._jinv[side]                                   # (n, 6, 6)
                rv = max(rv, float((np.abs(Ji @ tw) / self.qd_max).max()))
                ra = max(ra, float((np.abs(Ji @ dtw) / self.qdd_max).max()))
                if side in q:           # and at the instant's own joints: a wrist near its singularity
                    v, a, q[side] = self._along(side, T, q[side], tw, dtw)   # turns fast between the ends
                    rv, ra = max(rv, v), max(ra, a)
        return rv, ra / self.accel_allowance

    def _along(self, side: str, T: np.ndarray, q: np.ndarray, tw: np.ndarray,
               dtw: np.ndarray) -> tuple[float, float, np.ndarray]:
        """(peak joint speed / ``qd_max``, peak acceleration / ``qdd_max``, the joints (6,) rad) at the
        clamp pose ``T`` (4, 4) moving at twist ``tw`` and its rate ``dtw`` (6,): the joints one Newton step
        from ``q`` (the last instant's: a few mm away), the Jacobian there. A singular one counts nothing."""
        rates = np.empty((6, 2))
        rates[:, 0] = tw
        rates[:, 1] = dtw
        try:
            qn, v = self.kin[side].step_rates(T, q, tw, rates)
        except np.linalg.LinAlgError:
            return 0.0, 0.0, q
        return float((np.abs(v[:, 0]) / self.qd_max).max()), float((np.abs(v[:, 1]) / self.qdd_max).max()), qn
