"""The register map (messages.registers): signed 32-bit fixed point over two registers, word order, limits,
the command word and the input image's checks."""

import math

import numpy as np
import pytest

from flexsheet.arm.kinematics import Q_LOWER, Q_UPPER
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


def test_joint_vectors_encode_as_each_joint_alone_ties_to_even_and_bad_joints_named():
    """The 12-register joint vector equals the six (hi, lo) pairs of encode_i32 (ties at half a count go to
    the even count, as Python's round), decodes back through decode_i32's arithmetic, and a joint that does
    not fit is named."""
    rng = np.random.default_rng(7)
    q = np.concatenate([rng.normal(0.0, 2.0, 6), [0.5e-6, 1.5e-6, -2.5e-6, 2147.483647, -2147.483648, 0.0]])
    for v in q.reshape(-1, 6):
        regs = reg.encode_joints(v)
        assert regs == [w for k in range(6) for w in reg.encode_i32(v[k])]
        assert all(type(w) is int for w in regs)
        np.testing.assert_array_equal(reg.decode_joints(regs),
                                      [reg.decode_i32(regs[2 * k], regs[2 * k + 1]) for k in range(6)])
    assert reg.encode_joints([0.5e-6, 1.5e-6, 0, 0, 0, 0])[:4] == [0, 0, 0, 2]    # 0.5 -> 0, 1.5 -> 2
    with pytest.raises(ValueError, match=r"q\[J4\]"):
        reg.encode_joints([0.0, 0.0, 0.0, 3000.0, 0.0, 0.0])
    with pytest.raises(ValueError, match=r"q\[J2\].*finite"):
        reg.encode_joints([0.0, np.nan, 0.0, 0.0, 0.0, 0.0])
    with pytest.raises(ValueError, match=r"q\[J3\]\.lo"):
        reg.decode_joints([0, 0, 0, 0, 0, 70000] + [0] * 6)
