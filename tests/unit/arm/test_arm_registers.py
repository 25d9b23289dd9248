"""Register map encoding (signed 32-bit fixed point over two registers) and the controller core's checks."""

import math

import numpy as np
import pytest

from flexsheet.arm.kinematics import Q_HOME, Q_LOWER, Q_UPPER
from flexsheet.twin.controller import ControllerCore, WriteRejected
from messages import registers as reg


def test_word_order_is_high_word_first():
    assert reg.encode_i32(1e-6) == (0x0000, 0x0001)
    assert reg.encode_i32(65536e-6) == (0x0001, 0x0000)
    assert reg.encode_i32(-1e-6) == (0xFFFF, 0xFFFF)
    assert reg.encode_i32(reg.INT32_MIN * 1e-6) == (0x8000, 0x0000)
    assert reg.encode_i32(reg.INT32_MAX * 1e-6) == (0x7FFF, 0xFFFF)


@pytest.mark.parametrize("n", [reg.INT32_MIN, reg.INT32_MIN + 1, -65537, -65536, -1, 0, 1, 65535, 65536,
                               reg.INT32_MAX - 1, reg.INT32_MAX])
def test_round_trip_at_limits(n):
    hi, lo = reg.encode_i32(n * reg.SCALE)
    assert 0 <= hi <= 0xFFFF and 0 <= lo <= 0xFFFF
    assert round(reg.decode_i32(hi, lo) / reg.SCALE) == n


def test_joint_round_trip_random_and_resolution():
    rng = np.random.default_rng(3)
    for _ in range(200):
        q = rng.uniform(Q_LOWER, Q_UPPER)
        back = reg.decode_joints(reg.encode_joints(q))
        assert np.max(np.abs(back - q)) <= 0.5e-6 + 1e-12


@pytest.mark.parametrize("value", [2200.0, -2148.0, math.nan, math.inf, "abc", None])
def test_encode_out_of_range_or_not_finite_raises(value):
    with pytest.raises(ValueError, match="value"):
        reg.encode_i32(value)


@pytest.mark.parametrize("hi, lo", [(-1, 0), (0, 65536), (1.5, 0), (True, 0), (None, 3)])
def test_decode_malformed_register_raises(hi, lo):
    with pytest.raises(ValueError, match="register"):
        reg.decode_i32(hi, lo)


def test_command_word_and_input_image_checks():
    assert reg.check_command(reg.CMD_ENABLE | reg.CMD_RESET) == 5
    with pytest.raises(ValueError, match="undefined bits"):
        reg.check_command(0x0010)
    with pytest.raises(ValueError, match="42 registers"):
        reg.decode_input([0] * 10)
    with pytest.raises(ValueError, match="needs 12"):
        reg.decode_joints([0] * 11)
    assert reg.decode_status(reg.ST_ENABLED | reg.ST_FAULT) == ["enabled", "fault"]


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
