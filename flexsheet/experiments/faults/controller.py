"""Attacks on the controller twins (:mod:`flexsheet.twin.controller`, :mod:`flexsheet.twin.mxt_server`):
bursts inside one control cycle, a stranger's END, replayed CCounts, a STOP reset over the network. Each
returns a dict of counts; ``beyond_cap_rad`` is the executed motion past the per-cycle step check (must be
0)."""

from __future__ import annotations

import numpy as np

from flexsheet.arm.kinematics import Q_HOME, QD_MAX
from flexsheet.twin.controller import ControllerCore, WriteRejected
from flexsheet.twin.mxt_server import MxtCore
from messages import mxt
from messages import registers as reg

__all__ = ["mxt_burst", "modbus_burst", "mxt_stranger_end", "mxt_replay", "modbus_estop_network_reset"]

T_MXT, T_MB = 0.00711, 0.0071
OWNER, STRANGER = ("127.0.0.1", 40001), ("127.0.0.1", 40002)


def _cap(period: float) -> np.ndarray:
    return QD_MAX * period * 1.5          # the twins' step check (step_tolerance 1.5)


def _mxt_open(**kw) -> MxtCore:
    core = MxtCore(Q_HOME, period=T_MXT, now=0.0, **kw)
    core.receive(mxt.null_packet(0), 0.001, OWNER)
    return core


def mxt_burst(n: int = 60) -> dict:
    """``n`` MOVEs, each 0.02 rad further on J1, inside one 7.11 ms cycle."""
    core = _mxt_open()
    for k in range(1, n + 1):
        q = Q_HOME.copy()
        q[0] += 0.02 * k
        core.receive(mxt.move_packet(q, k), T_MXT + 0.001 + 1e-5 * k, OWNER)
    core.advance(2 * T_MXT + 1e-6)
    moved = np.abs(core.active - Q_HOME)
    return {"packets": n, "executed_step_rad": float(moved.max()),
            "beyond_cap_rad": float(np.max(np.maximum(moved - _cap(T_MXT), 0.0))), "refused": core.refused,
            "extra": core.extra}


def modbus_burst(n: int = 20) -> dict:
    """``n`` target writes, each 0.9 of a step beyond the last, inside one period."""
    core = ControllerCore(Q_HOME, period=T_MB, now=0.0)
    core.write_holding(reg.HR_COMMAND, [reg.CMD_ENABLE], 0.0)
    q, refused = Q_HOME.copy(), 0
    for k in range(n):
        q = q + 0.9 * _cap(T_MB)
        try:
            core.write_holding(reg.HR_WATCHDOG, [k + 1, *reg.encode_joints(q)], 1e-4 * (k + 1))
        except WriteRejected:
            refused += 1
    core.advance(T_MB + 1e-6)
    moved = np.abs(core.active - Q_HOME)
    return {"writes": n, "executed_step_rad": float(moved.max()),
            "beyond_cap_rad": float(np.max(np.maximum(moved - _cap(T_MB), 0.0))), "refused": refused}


def mxt_stranger_end() -> dict:
    """An END from another source port while the owner streams."""
    core = _mxt_open()
    core.receive(mxt.end_packet(1), 0.002, STRANGER)
    still = core.session == "open"
    answered = core.receive(mxt.move_packet(Q_HOME + 0.5 * _cap(T_MXT), 1), 0.003, OWNER) is not None
    return {"owner_session_open": bool(still and answered), "foreign": core.foreign, "ends": core.ends}


def mxt_replay() -> dict:
    """A replayed MOVE, an out-of-order one and an old END."""
    core = _mxt_open()
    q5 = Q_HOME + 0.5 * _cap(T_MXT)
    core.receive(mxt.move_packet(q5, 5), 0.002, OWNER)
    core.receive(mxt.move_packet(q5, 5), 0.003, OWNER)
    core.receive(mxt.move_packet(Q_HOME, 3), 0.004, OWNER)
    core.receive(mxt.end_packet(4), 0.005, OWNER)
    return {"sent_bad": 3, "dropped_counted": core.replayed, "session_open": core.session == "open"}


def modbus_estop_network_reset() -> dict:
    """STOP, then RESET|ENABLE and RESET edges over Modbus; then the twin's local reset."""
    core = ControllerCore(Q_HOME, period=T_MB, now=0.0)
    t = 0.0
    for cmd in (reg.CMD_ENABLE, reg.CMD_STOP, 0, reg.CMD_RESET | reg.CMD_ENABLE, 0, reg.CMD_RESET,
                reg.CMD_ENABLE):
        t += T_MB
        try:
            core.write_holding(reg.HR_COMMAND, [cmd], t)
        except WriteRejected:
            pass
    latched = core.fault == reg.FAULT_ESTOP
    cleared = core.local_reset(t + T_MB)
    return {"estop_latched_after_network_reset": bool(latched), "network_resets_refused":
            core.network_resets_refused, "local_reset_clears": bool(cleared and core.fault == reg.FAULT_NONE)}
