"""The two-arm span guard (pure): the sheet couples the two clamps, so one arm's step must not pull the span
between them further outside its band while the partner lags.

:class:`SpanGuard` holds the band (``span_band`` [lo, hi] m of the bridge's parameters), the partner clamp's
measured position (its ``ArmJointState.pose``) and whether the partner waits on its own guard (its
``bridge_status`` ``wait:span``); :meth:`SpanGuard.worse` says whether a step waits. The bridge's tracker
(:class:`flexsheet.arm.tracking.TargetTracker`) asks it for each streamed step.
"""

from __future__ import annotations

import math

import numpy as np

from flexsheet.arm.kinematics import ArmKinematics
from flexsheet.model.vec import vnorm

__all__ = ["SpanGuard"]


class SpanGuard:
    """The clamp span one arm keeps with its partner. ``kin``: this arm's :class:`ArmKinematics` (its clamp's
    position from joints). Without a band (:meth:`set_band`) or a partner state (:attr:`peer_clamp`) no step
    waits."""

    def __init__(self, kin: ArmKinematics) -> None:
        self.kin = kin
        #: (3,) m, display frame: the partner clamp's measured position (its ``ArmJointState.pose``), or None
        self.peer_clamp: np.ndarray | None = None
        #: s: the stamp of that measurement (its ``ArmJointState`` header), or None
        self.peer_stamp: float | None = None
        #: whether this arm's last step waited on the guard (``wait:span``)
        self.waiting = False
        #: whether the partner's last state said it waits on its guard
        self.peer_waiting = False
        #: (lo, hi) m: the clamp span kept with the partner, or None: no guard
        self.band: tuple[float, float] | None = None
        #: steps that waited because they would have taken the span further outside the band
        self.waits = 0
        #: clamp positions of the last two joint vectors judged (joints'
        #: bytes -> (3,) m): a step starts where the last one ended
        self._points: dict[bytes, np.ndarray] = {}

    def set_band(self, band) -> None:
        """Keep the clamp span within ``band`` = (lo, hi) m of the partner's clamp (None: no guard). Raises
        ``ValueError`` unless 0 < lo < hi."""
        if band is None:
            self.band = None
            return
        lo, hi = (float(x) for x in band)
        if not (0.0 < lo < hi and math.isfinite(hi)):
            raise ValueError(f"span_band must be [lo, hi] m with 0 < lo < hi, got {list(band)!r}")
        self.band = (lo, hi)

    def outside(self, q: np.ndarray, peer: np.ndarray | None = None, band=None) -> float:
        """How far (m) the clamp at joints ``q`` (6,) rad lies outside ``band`` (default :attr:`band`) from
        the partner's clamp ``peer`` (3,) m (default :attr:`peer_clamp`); 0 inside."""
        peer = self.peer_clamp if peer is None else peer
        lo, hi = self.band if band is None else band
        s = vnorm(self._point(q) - peer)
        return max(lo - s, s - hi, 0.0)

    def _point(self, q) -> np.ndarray:
        """The clamp's position (3,) m at joints ``q`` (6,) rad (remembered for the last two)."""
        key = np.asarray(q, float).tobytes()
        p = self._points.get(key)
        if p is None:
            if len(self._points) >= 2:
                self._points.pop(next(iter(self._points)))
            p = self._points[key] = self.kin.fk(q)[:3, 3]
        return p

    def worse(self, q_from, q_to, peer: np.ndarray | None = None, band=None) -> bool:
        """Whether moving this clamp from joints ``q_from`` to ``q_to`` (6,) rad takes the clamp span further
        outside ``band`` (default :attr:`band`) from the partner's clamp ``peer`` (default its measured one,
        :attr:`peer_clamp`); counted in :attr:`waits` and :attr:`waiting`. False without a band or a partner
        state. Such a step waits for the partner, unless the partner waits too (:attr:`peer_waiting`): then
        both step, as the planner's targets keep the span; two arms each waiting for the other would wait for
        ever."""
        peer = self.peer_clamp if peer is None else peer
        band = self.band if band is None else band
        if band is None or peer is None:
            return False
        out_from = self.outside(q_from, peer, band)   # first: the last step's end, remembered (_point)
        out_to = self.outside(q_to, peer, band)
        if out_to > 0.0 and out_to > out_from + 1e-6 and not self.peer_waiting:
            self.waits += 1
            self.waiting = True
            return True
        self.waiting = False
        return False
