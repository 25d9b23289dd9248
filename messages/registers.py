"""The arm controller's Modbus TCP register map and its encoding (pure; see docs/register_map.md).

For controllers and PLC gateways that expose Modbus TCP, and the Modbus twin; a Mitsubishi MELFA controller is
driven over real-time external control instead (:mod:`messages.mxt`). :class:`ControllerState` is also the
protocol-neutral controller state the bridge's MXT backend fills (with synthesised STATUS bits).

Style follows robot Modbus servers such as Universal Robots' map: holding registers (function codes 03, 06,
16) carry what the client commands, input registers (04) what the controller measures. Device id: any (the
twin answers every id). Addresses are 0-based protocol addresses.

Fixed-point: a joint angle is a signed 32-bit integer in micro-radians (``SCALE = 1e-6`` rad per LSB,
range ±2147.48 rad), split over two 16-bit registers, **high word first** (big-endian word order, "ABCD":
register k holds bits 31..16, register k+1 bits 15..0, each register itself big-endian on the wire as
Modbus requires). Velocities use the same layout in micro-radians per second.

Holding registers
  0  COMMAND     bit 0 ENABLE (servo on, follow targets), bit 1 STOP (e-stop, latched), bit 2 RESET
                 (a 0→1 edge clears faults whose cause is gone). Other bits set → rejected (ILLEGAL DATA
  VALUE). 1  WATCHDOG    counter the client changes every cycle (any change counts; wraps 65535 → 0). 2..13
  TARGET   J1..J6 joint targets, int32 µrad, 2 registers each. Must be written as whole pairs.

Input registers
  0  STATUS      bits, see ``ST_*``.
  1  FAULT       fault code, see ``FAULT_*`` (0 = none).
  2  REJECT      reason the last rejected write was refused, see ``REJ_*`` (0 = none since reset).
  3..4 CYCLE     controller cycle counter, uint32, high word first.
  5..16 POSITION measured joints J1..J6, int32 µrad.
  17..28 VELOCITY measured joint velocities, int32 µrad/s.
  29 WATCHDOG_ECHO last watchdog value seen.
  30..41 ACTIVE  target the servo is tracking now, int32 µrad.
"""

from __future__ import annotations

import math
import struct
from collections.abc import Sequence

import numpy as np

__all__ = [
    "SCALE", "INT32_MIN", "INT32_MAX", "N_JOINTS",
    "HR_COMMAND", "HR_WATCHDOG", "HR_TARGET", "HR_COUNT",
    "IR_STATUS", "IR_FAULT", "IR_REJECT", "IR_CYCLE", "IR_POSITION", "IR_VELOCITY", "IR_WATCHDOG_ECHO",
    "IR_ACTIVE", "IR_COUNT",
    "CMD_ENABLE", "CMD_STOP", "CMD_RESET", "CMD_MASK",
    "ST_ENABLED", "ST_MOVING", "ST_FAULT", "ST_ESTOP", "ST_HOLD", "ST_WATCHDOG_OK", "ST_REJECTED",
    "ST_IN_POSITION", "FAULT_NONE", "FAULT_WATCHDOG", "FAULT_ESTOP",
    "REJ_NONE", "REJ_COMMAND_BITS", "REJ_TARGET_LIMIT", "REJ_TARGET_STEP", "REJ_PARTIAL_PAIR", "REJ_ADDRESS",
    "STATUS_NAMES", "FAULT_NAMES", "REJECT_NAMES",
    "encode_i32", "decode_i32", "encode_joints", "decode_joints", "encode_u32", "decode_u32",
    "check_register", "check_command", "decode_status", "ControllerState", "decode_input",
]

SCALE = 1e-6                      #: rad (or rad/s) per least significant bit
INT32_MIN = -(2 ** 31)
INT32_MAX = 2 ** 31 - 1
N_JOINTS = 6

HR_COMMAND = 0
HR_WATCHDOG = 1
HR_TARGET = 2
HR_COUNT = HR_TARGET + 2 * N_JOINTS          # 14 holding registers

IR_STATUS = 0
IR_FAULT = 1
IR_REJECT = 2
IR_CYCLE = 3
IR_POSITION = 5
IR_VELOCITY = IR_POSITION + 2 * N_JOINTS     # 17
IR_WATCHDOG_ECHO = IR_VELOCITY + 2 * N_JOINTS  # 29
IR_ACTIVE = IR_WATCHDOG_ECHO + 1             # 30
IR_COUNT = IR_ACTIVE + 2 * N_JOINTS          # 42 input registers

CMD_ENABLE = 1 << 0
CMD_STOP = 1 << 1
CMD_RESET = 1 << 2
CMD_MASK = CMD_ENABLE | CMD_STOP | CMD_RESET

ST_ENABLED = 1 << 0       #: servo on and following targets
ST_MOVING = 1 << 1        #: some joint speed above 1e-4 rad/s
ST_FAULT = 1 << 2         #: a fault is latched (see FAULT)
ST_ESTOP = 1 << 3         #: e-stop requested or latched
ST_HOLD = 1 << 4          #: holding position (fault, e-stop or disabled)
ST_WATCHDOG_OK = 1 << 5   #: the watchdog counter changed within the last 3 periods
ST_REJECTED = 1 << 6      #: the last write was rejected (see REJECT)
ST_IN_POSITION = 1 << 7   #: every joint within 1e-4 rad of the active target and still

FAULT_NONE = 0
FAULT_WATCHDOG = 1
FAULT_ESTOP = 2

REJ_NONE = 0
REJ_COMMAND_BITS = 1      #: command word with undefined bits
REJ_TARGET_LIMIT = 2      #: a joint target outside the joint limits
REJ_TARGET_STEP = 3       #: a joint target step larger than the speed limit allows in one period
REJ_PARTIAL_PAIR = 4      #: a write that splits a 32-bit target pair
REJ_ADDRESS = 5           #: write outside the holding registers

STATUS_NAMES = {ST_ENABLED: "enabled", ST_MOVING: "moving", ST_FAULT: "fault", ST_ESTOP: "estop",
                ST_HOLD: "hold", ST_WATCHDOG_OK: "watchdog_ok", ST_REJECTED: "rejected",
                ST_IN_POSITION: "in_position"}
FAULT_NAMES = {FAULT_NONE: "none", FAULT_WATCHDOG: "watchdog", FAULT_ESTOP: "estop"}
REJECT_NAMES = {REJ_NONE: "none", REJ_COMMAND_BITS: "command_bits", REJ_TARGET_LIMIT: "target_limit",
                REJ_TARGET_STEP: "target_step", REJ_PARTIAL_PAIR: "partial_pair", REJ_ADDRESS: "address"}


def check_register(name: str, value) -> int:
    """Return ``value`` as an int if it is a valid 16-bit register (int in 0..65535, not bool).

    Raises ``ValueError`` naming ``name`` and the value otherwise (e.g. negative, > 65535, float, None).
    """
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise ValueError(f"register {name} must be an int in 0..65535, got {value!r}")
    v = int(value)
    if not 0 <= v <= 0xFFFF:
        raise ValueError(f"register {name} must be in 0..65535, got {v}")
    return v


def encode_i32(value: float, scale: float = SCALE, name: str = "value") -> tuple[int, int]:
    """Encode a real ``value`` (e.g. rad) as round(value/scale) in int32, returned as (high word, low word).

    Raises ``ValueError`` naming ``name`` if the value is not finite or does not fit int32 after scaling.
    """
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a real number, got {value!r}") from None
    if not math.isfinite(x) or not math.isfinite(x / scale):
        raise ValueError(f"{name} must be finite (also after scaling by 1/{scale}), got {x!r}")
    n = round(x / scale)
    if not INT32_MIN <= n <= INT32_MAX:
        raise ValueError(f"{name}={x!r} does not fit a signed 32-bit fixed point at scale {scale}")
    hi, lo = struct.unpack(">HH", struct.pack(">i", n))
    return hi, lo


def decode_i32(hi, lo, scale: float = SCALE, name: str = "value") -> float:
    """Inverse of :func:`encode_i32`: registers (high, low) → value·scale. Raises ``ValueError`` on bad
    registers."""
    h = check_register(f"{name}.hi", hi)
    lo_ = check_register(f"{name}.lo", lo)
    (n,) = struct.unpack(">i", struct.pack(">HH", h, lo_))
    return n * scale


def encode_u32(value: int, name: str = "value") -> tuple[int, int]:
    """Unsigned 32-bit int → (high, low) registers; wraps modulo 2³² (counters). ``ValueError`` if not int."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise ValueError(f"{name} must be an int, got {value!r}")
    v = int(value) & 0xFFFFFFFF
    return v >> 16, v & 0xFFFF


def decode_u32(hi, lo, name: str = "value") -> int:
    """(high, low) registers → unsigned 32-bit int. Raises ``ValueError`` on bad registers."""
    return (check_register(f"{name}.hi", hi) << 16) | check_register(f"{name}.lo", lo)


def encode_joints(q, scale: float = SCALE, name: str = "q") -> list[int]:
    """(6,) joint values (rad or rad/s) → 12 registers, high word first per joint. ``ValueError`` on bad
    input (naming the joint, as :func:`encode_i32`)."""
    a = np.asarray(q, dtype=float) if not isinstance(q, str) else None
    if a is None or a.shape != (N_JOINTS,):
        raise ValueError(f"{name} must be a ({N_JOINTS},) vector, got {q!r}")
    with np.errstate(all="ignore"):
        n = np.rint(a / scale)        # half to even, as round(): the same integers, the vector at once
    if not (np.isfinite(n).all() and (n >= INT32_MIN).all() and (n <= INT32_MAX).all()):
        regs: list[int] = []
        for k in range(N_JOINTS):     # the first bad joint, named
            regs.extend(encode_i32(a[k], scale, f"{name}[J{k + 1}]"))
        return regs
    w = n.astype(np.int64).astype(np.uint32)
    return np.column_stack([w >> 16, w & 0xFFFF]).ravel().tolist()


def _register_list(regs, what: str) -> list:
    """``regs`` as a list if it is a list/tuple/ndarray of registers, else ``ValueError`` naming ``what``."""
    if not isinstance(regs, (list, tuple, np.ndarray)) or (isinstance(regs, np.ndarray) and regs.ndim != 1):
        raise ValueError(f"{what} must be a sequence of 16-bit registers, got {type(regs).__name__}")
    return list(regs)


def decode_joints(regs: Sequence[int], scale: float = SCALE, name: str = "q") -> np.ndarray:
    """12 registers → (6,) float64 (rad or rad/s). Raises ``ValueError`` naming the bad register or length."""
    regs = _register_list(regs, name)
    if len(regs) != 2 * N_JOINTS:
        raise ValueError(f"{name} needs {2 * N_JOINTS} registers, got {len(regs)}")
    if all(type(r) is int and 0 <= r <= 0xFFFF for r in regs):
        w = np.array(regs, dtype=np.uint32).reshape(N_JOINTS, 2)
        return ((w[:, 0] << 16) | w[:, 1]).astype(np.int32).astype(float) * scale
    return np.array([decode_i32(regs[2 * k], regs[2 * k + 1], scale, f"{name}[J{k + 1}]")
                     for k in range(N_JOINTS)])


def check_command(value) -> int:
    """Validate a COMMAND word: an int register with only ENABLE/STOP/RESET bits. Raises ``ValueError``."""
    v = check_register("COMMAND", value)
    if v & ~CMD_MASK:
        raise ValueError(f"COMMAND has undefined bits set: 0x{v:04x} (allowed mask 0x{CMD_MASK:04x})")
    return v


def decode_status(status: int) -> list[str]:
    """Names of the STATUS bits set in ``status`` (e.g. ["enabled", "watchdog_ok"]). ``ValueError`` if bad."""
    v = check_register("STATUS", status)
    return [n for bit, n in STATUS_NAMES.items() if v & bit]


class ControllerState:
    """Decoded input-register image (see module doc): plain attributes, SI units.

    ``status`` int, ``fault`` int, ``reject`` int, ``cycle`` int, ``position`` (6,) rad, ``velocity`` (6,)
    rad/s, ``watchdog_echo`` int, ``active`` (6,) rad.
    """

    __slots__ = ("status", "fault", "reject", "cycle", "position", "velocity", "watchdog_echo", "active")

    def __init__(self, status, fault, reject, cycle, position, velocity, watchdog_echo, active):
        self.status, self.fault, self.reject, self.cycle = status, fault, reject, cycle
        self.position, self.velocity, self.watchdog_echo, self.active = (position, velocity, watchdog_echo,
                                                                         active)

    def has(self, bit: int) -> bool:
        """True if STATUS bit ``bit`` (an ``ST_*`` constant) is set."""
        return bool(self.status & bit)


def decode_input(regs: Sequence[int]) -> ControllerState:
    """Decode the ``IR_COUNT`` input registers into a :class:`ControllerState`. ``ValueError`` on bad
    length/values."""
    regs = _register_list(regs, "input image")
    if len(regs) != IR_COUNT:
        raise ValueError(f"input image needs {IR_COUNT} registers, got {len(regs)}")
    return ControllerState(
        status=check_register("STATUS", regs[IR_STATUS]),
        fault=check_register("FAULT", regs[IR_FAULT]),
        reject=check_register("REJECT", regs[IR_REJECT]),
        cycle=decode_u32(regs[IR_CYCLE], regs[IR_CYCLE + 1], "CYCLE"),
        position=decode_joints(regs[IR_POSITION:IR_POSITION + 12], name="POSITION"),
        velocity=decode_joints(regs[IR_VELOCITY:IR_VELOCITY + 12], name="VELOCITY"),
        watchdog_echo=check_register("WATCHDOG_ECHO", regs[IR_WATCHDOG_ECHO]),
        active=decode_joints(regs[IR_ACTIVE:IR_ACTIVE + 12], name="ACTIVE"),
    )
