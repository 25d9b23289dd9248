"""The controller twin's core (flexsheet.twin.controller): malformed writes rejected without motion, the
watchdog, the e-stop latch and its local reset."""

import numpy as np
import pytest

from flexsheet.arm.kinematics import Q_HOME
from flexsheet.twin.controller import ControllerCore, WriteRejected
from messages import registers as reg


def _enabled_core(now=0.0):
    core = ControllerCore(Q_HOME, now=now)
    core.write_holding(reg.HR_COMMAND, [reg.CMD_ENABLE], now)
    return core


def test_malformed_writes_rejected_without_motion():
    core = _enabled_core()
    q0 = core.servo.q.copy()
    bad_writes = [
        (reg.HR_COMMAND, [0x0100], reg.REJ_COMMAND_BITS),
        (reg.HR_TARGET + 1, [0, 0], reg.REJ_PARTIAL_PAIR),              # splits J1/J2 pairs
        (reg.HR_TARGET, reg.encode_joints(Q_HOME + [3.0, 0, 0, 0, 0, 0]), reg.REJ_TARGET_LIMIT),
        (reg.HR_TARGET, reg.encode_joints(Q_HOME + [0.2, 0, 0, 0, 0, 0]), reg.REJ_TARGET_STEP),
        (reg.HR_TARGET, [70000] + [0] * 11, reg.REJ_ADDRESS),           # not a 16-bit register
        (12, [0, 0, 0, 0], reg.REJ_ADDRESS),                             # beyond the map
    ]
    t = 0.0
    for address, values, code in bad_writes:
        before = list(core.holding)
        with pytest.raises(WriteRejected) as exc:
            core.write_holding(address, values, t)
        assert exc.value.code == code and str(exc.value)
        assert core.holding == before
        assert core.status_word(t) & reg.ST_REJECTED
        assert core.input_registers(t)[reg.IR_REJECT] == code
        t += core.period
        core.write_holding(reg.HR_WATCHDOG, [int(t * 1000) & 0xFFFF], t)   # keep the watchdog alive
        core.advance(t)
    assert np.max(np.abs(core.servo.q - q0)) < 1e-12
    assert core.enabled and core.fault == reg.FAULT_NONE


def test_watchdog_fault_after_three_periods_and_reset():
    core = _enabled_core()
    T = core.period
    core.write_holding(reg.HR_WATCHDOG, [1], 0.0)
    core.advance(3 * T + 1e-6)
    assert core.enabled and core.fault == reg.FAULT_NONE          # exactly 3 periods: still fine
    core.advance(4 * T + 1e-6)
    assert not core.enabled and core.fault == reg.FAULT_WATCHDOG
    st = core.status_word(4 * T)
    assert st & reg.ST_FAULT and st & reg.ST_HOLD and not st & reg.ST_WATCHDOG_OK
    # recovery: counter running again, RESET edge with ENABLE
    now = 5 * T
    core.write_holding(reg.HR_WATCHDOG, [2], now)
    core.write_holding(reg.HR_COMMAND, [reg.CMD_RESET | reg.CMD_ENABLE], now)
    assert core.enabled and core.fault == reg.FAULT_NONE
    assert np.allclose(core.active, core.servo.q)                  # resumes from where it holds


def test_estop_latches_until_the_local_reset():
    core = _enabled_core()
    core.write_holding(reg.HR_COMMAND, [reg.CMD_STOP | reg.CMD_ENABLE], 0.0)
    assert not core.enabled and core.fault == reg.FAULT_ESTOP
    core.write_holding(reg.HR_COMMAND, [reg.CMD_STOP | reg.CMD_RESET | reg.CMD_ENABLE], 0.0)
    assert core.fault == reg.FAULT_ESTOP                             # reset ignored while STOP held
    core.write_holding(reg.HR_COMMAND, [reg.CMD_ENABLE], 0.0)
    assert core.fault == reg.FAULT_ESTOP and not core.enabled        # no reset edge yet
    core.write_holding(reg.HR_COMMAND, [reg.CMD_RESET | reg.CMD_ENABLE], 0.0)
    assert core.fault == reg.FAULT_ESTOP and not core.enabled        # a network RESET never clears an e-stop
    assert core.network_resets_refused == 1                          # (STOP|RESET is a stop)
    assert core.local_reset(0.0)                                     # the operator's reset at the controller
    assert core.fault == reg.FAULT_NONE and not core.enabled         # held until a client enables
    assert not core.status_word(0.0) & reg.ST_ESTOP
    core.write_holding(reg.HR_COMMAND, [reg.CMD_ENABLE], 0.0)
    assert core.enabled
