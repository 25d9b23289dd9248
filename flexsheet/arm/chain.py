"""One arm's chain as its bridge runs it, assembled in one place: the IK's kinematics (the joint limits less
``limit_margin``), the measured joints' kinematics (the full limits), the target tracker and the stream
limiter, from the bridge's settings (:class:`~flexsheet.arm.bridge_config.BridgeConfig`: their one owner).
The bridge node, the arm bench and the planner's stroke model build it here. Units: m, rad, s."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from flexsheet.arm.bridge_config import BridgeConfig
from flexsheet.arm.kinematics import Q_LOWER, Q_UPPER, QD_MAX, ArmKinematics
from flexsheet.arm.limiter import StreamLimiter
from flexsheet.arm.tracking import TargetTracker

__all__ = ["BridgeChain", "bridge_chain"]


@dataclass(frozen=True)
class BridgeChain:
    """``kin``: IK within the joint limits less the margin; ``fk``: the measured joints' FK (full limits);
    ``tracker``: the :class:`TargetTracker` on ``kin``; ``limiter``: the :class:`StreamLimiter` (speed
    ``QD_MAX × speed_scale`` rad/s, acceleration ``accel_scale ×`` that per s)."""

    kin: ArmKinematics
    fk: ArmKinematics
    tracker: TargetTracker
    limiter: StreamLimiter


def bridge_chain(side: str, base, period: float, cfg=None, q0=None) -> BridgeChain:
    """The chain of arm ``side`` ("left"/"right") on ``base`` ((x, y, z, yaw) or (4, 4) T_display_base) at
    cycle ``period`` s, with ``cfg``'s ``limit_margin``, ``target_timeout``, ``max_ik_jump``, ``span_band``,
    ``speed_scale`` and ``accel_scale`` (a :class:`BridgeConfig` or the bridge's params; None: the
    defaults); the limiter starts at rest at ``q0`` (6,) rad (None: the zero joints clipped into the limits,
    reseeded from the controller's first state). Raises ``ValueError`` on a bad side, base or setting."""
    cfg = cfg if cfg is not None else BridgeConfig()
    m = cfg.limit_margin
    kin = ArmKinematics(side, base, Q_LOWER + m, Q_UPPER - m)
    tracker = TargetTracker(kin, cfg.target_timeout, cfg.max_ik_jump)
    tracker.span.set_band(cfg.span_band)
    qd = QD_MAX * cfg.speed_scale
    start = np.clip(np.zeros(6), Q_LOWER, Q_UPPER) if q0 is None else np.asarray(q0, float)
    limiter = StreamLimiter(start, period, qd, qd * cfg.accel_scale, Q_LOWER, Q_UPPER, m)
    return BridgeChain(kin, ArmKinematics(side, base), tracker, limiter)
