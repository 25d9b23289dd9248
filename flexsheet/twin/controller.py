"""The arm controller twin's logic, independent of Modbus transport (pure; time is passed in).

:class:`ControllerCore` owns the register image of docs/register_map.md, validates every write (a refused write
changes nothing and records a reject code), runs the joint servo (:mod:`.servo`) in fixed periods, and
implements the watchdog (counter unchanged for more than ``watchdog_periods`` periods while enabled → hold and
``FAULT_WATCHDOG``), the e-stop (COMMAND.STOP → hold and ``FAULT_ESTOP``, latched) and the fault reset
(a 0→1 edge of COMMAND.RESET with STOP clear). Holding means the active target is frozen at the joints measured
when the hold began; the servo brakes to it under its acceleration limit.

Write checks (mirroring a real-time external-control controller, which refuses a too-large step rather than
executing it): targets inside the joint limits, and while enabled each joint's step from the active target
≤ ``qd_max · period · step_tolerance``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from flexsheet.twin.servo import JointServo, ServoParams
from messages import registers as reg

__all__ = ["ControllerCore", "WriteRejected"]


class WriteRejected(ValueError):
    """A Modbus write the controller refuses; ``code`` is the ``REJ_*`` reason, the message says why."""

    def __init__(self, code: int, message: str) -> None:
        super().__init__(message)
        self.code = code


class ControllerCore:
    """Register-level model of one RV-1A controller.

    Parameters
    ----------
    q0 : (6,) rad, initial joints.
    period : s, servo/control period (default 0.0071, the RV-1A real-time external-control period).
    servo : :class:`ServoParams`, optional.
    watchdog_periods : int, periods the watchdog counter may stay unchanged while enabled (default 3).
    step_tolerance : float ≥ 1, allowed multiple of ``qd_max·period`` per written target step (default 1.5).
    now : float, s, the clock's current value (monotonic seconds).
    """

    def __init__(self, q0, period: float = 0.0071, servo: ServoParams | None = None,
                 watchdog_periods: int = 3, step_tolerance: float = 1.5, now: float = 0.0) -> None:
        if not (period > 0.0 and math.isfinite(period)):
            raise ValueError(f"period must be > 0 s, got {period!r}")
        if watchdog_periods < 1:
            raise ValueError(f"watchdog_periods must be >= 1, got {watchdog_periods!r}")
        if not step_tolerance >= 1.0:
            raise ValueError(f"step_tolerance must be >= 1, got {step_tolerance!r}")
        self.period = float(period)
        self.watchdog_periods = int(watchdog_periods)
        self.step_tolerance = float(step_tolerance)
        self.servo = JointServo(q0, servo)
        self.holding = [0] * reg.HR_COUNT
        self.holding[reg.HR_TARGET:reg.HR_TARGET + 12] = reg.encode_joints(self.servo.q)
        self.active = self.servo.q.copy()
        self.enabled = False
        self.fault = reg.FAULT_NONE
        self.reject = reg.REJ_NONE
        self.last_rejected = False
        self.cycle = 0
        self.t_sim = float(now)
        self.wd_value = 0
        self.wd_changed_at = float(now)
        self.rejections = 0
        self.writes = 0
        self.target_log: list[np.ndarray] | None = None   # set to [] to record accepted targets (tests)

    # ------------------------------------------------------------------ writes
    def write_holding(self, address: int, values: Sequence[int], now: float) -> None:
        """Apply a write of ``values`` at holding ``address``; raise :class:`WriteRejected` and change nothing
        if any register is malformed, the command has undefined bits, a target pair is split, or a target is
        out of limits / too large a step."""
        try:
            vals = [reg.check_register(f"HR[{address + i}]", v) for i, v in enumerate(values)]
        except ValueError as e:
            self._reject(reg.REJ_ADDRESS, str(e))
        end = address + len(vals)
        if address < 0 or end > reg.HR_COUNT or not vals:
            self._reject(reg.REJ_ADDRESS, f"write {address}..{end - 1} outside holding registers 0..{reg.HR_COUNT - 1}")
        new = list(self.holding)
        new[address:end] = vals
        t_lo, t_hi = reg.HR_TARGET, reg.HR_TARGET + 12
        touches_targets = address < t_hi and end > t_lo
        if touches_targets and ((max(address, t_lo) - t_lo) % 2 or (min(end, t_hi) - t_lo) % 2):
            self._reject(reg.REJ_PARTIAL_PAIR, f"write {address}..{end - 1} splits a 32-bit joint target pair")
        if address <= reg.HR_COMMAND < end:
            try:
                reg.check_command(new[reg.HR_COMMAND])
            except ValueError as e:
                self._reject(reg.REJ_COMMAND_BITS, str(e))
        target = None
        if touches_targets:
            target = reg.decode_joints(new[t_lo:t_hi], name="TARGET")
            p = self.servo.p
            bad = np.flatnonzero((target < p.q_lower) | (target > p.q_upper))
            if bad.size:
                k = int(bad[0])
                self._reject(reg.REJ_TARGET_LIMIT, f"TARGET J{k + 1}={target[k]:.6f} rad outside "
                                                   f"[{p.q_lower[k]:.6f}, {p.q_upper[k]:.6f}]")
            if self.enabled:
                step = np.abs(target - self.active)
                cap = p.qd_max * self.period * self.step_tolerance
                over = np.flatnonzero(step > cap)
                if over.size:
                    k = int(over[0])
                    self._reject(reg.REJ_TARGET_STEP, f"TARGET J{k + 1} step {step[k]:.6f} rad > "
                                                      f"{cap[k]:.6f} rad allowed per period")
        # accepted: commit
        self.writes += 1
        self.last_rejected = False
        old_cmd = self.holding[reg.HR_COMMAND]
        self.holding = new
        if address <= reg.HR_WATCHDOG < end and new[reg.HR_WATCHDOG] != self.wd_value:
            self.wd_value = new[reg.HR_WATCHDOG]
            self.wd_changed_at = now
        if address <= reg.HR_COMMAND < end:
            self._command(old_cmd, new[reg.HR_COMMAND], now)
        if target is not None and self.enabled:
            self.active = target
            if self.target_log is not None:
                self.target_log.append(target.copy())

    def _reject(self, code: int, message: str):
        self.reject = code
        self.last_rejected = True
        self.rejections += 1
        raise WriteRejected(code, message)

    def _command(self, old: int, cmd: int, now: float) -> None:
        if cmd & reg.CMD_STOP:
            self._hold()
            self.fault = reg.FAULT_ESTOP
            return
        if (cmd & reg.CMD_RESET) and not (old & reg.CMD_RESET):
            self.fault = reg.FAULT_NONE
            self.reject = reg.REJ_NONE
            self.wd_changed_at = now
        if cmd & reg.CMD_ENABLE and self.fault == reg.FAULT_NONE:
            if not self.enabled:
                self.enabled = True
                self.active = self.servo.q.copy()
                self.wd_changed_at = now
        elif self.enabled:
            self._hold()

    def _hold(self) -> None:
        self.enabled = False
        self.active = self.servo.q.copy()

    # ------------------------------------------------------------------ time
    def advance(self, now: float, max_steps: int = 20) -> int:
        """Run servo periods up to time ``now`` (s, same clock as the writes); returns the periods run.

        At most ``max_steps`` periods are run per call (a stalled caller does not replay a long gap: the
        simulated time jumps to ``now``). The watchdog is checked each period.
        """
        n = 0
        while self.t_sim + self.period <= now and n < max_steps:
            self.t_sim += self.period
            self._watchdog(self.t_sim)
            self.servo.step(self.active, self.period)
            self.cycle = (self.cycle + 1) & 0xFFFFFFFF
            n += 1
        if self.t_sim + self.period <= now:
            self.t_sim = now
        return n

    def _watchdog(self, t: float) -> None:
        if self.enabled and t - self.wd_changed_at > self.watchdog_periods * self.period + 1e-9:
            self._hold()
            self.fault = reg.FAULT_WATCHDOG

    # ------------------------------------------------------------------ reads
    def status_word(self, now: float) -> int:
        """STATUS register value at time ``now``."""
        s = 0
        if self.enabled:
            s |= reg.ST_ENABLED
        else:
            s |= reg.ST_HOLD
        if float(np.max(np.abs(self.servo.v))) > 1e-4:
            s |= reg.ST_MOVING
        elif float(np.max(np.abs(self.servo.q - self.active))) < 1e-4:
            s |= reg.ST_IN_POSITION
        if self.fault != reg.FAULT_NONE:
            s |= reg.ST_FAULT
        if self.fault == reg.FAULT_ESTOP or self.holding[reg.HR_COMMAND] & reg.CMD_STOP:
            s |= reg.ST_ESTOP
        if now - self.wd_changed_at <= self.watchdog_periods * self.period + 1e-9:
            s |= reg.ST_WATCHDOG_OK
        if self.last_rejected:
            s |= reg.ST_REJECTED
        return s

    def input_registers(self, now: float) -> list[int]:
        """The ``IR_COUNT`` input registers (see :mod:`.registers`) at time ``now``."""
        r = [0] * reg.IR_COUNT
        r[reg.IR_STATUS] = self.status_word(now)
        r[reg.IR_FAULT] = self.fault
        r[reg.IR_REJECT] = self.reject
        r[reg.IR_CYCLE:reg.IR_CYCLE + 2] = reg.encode_u32(self.cycle)
        r[reg.IR_POSITION:reg.IR_POSITION + 12] = reg.encode_joints(self.servo.q, name="POSITION")
        r[reg.IR_VELOCITY:reg.IR_VELOCITY + 12] = reg.encode_joints(self.servo.v, name="VELOCITY")
        r[reg.IR_WATCHDOG_ECHO] = self.wd_value
        r[reg.IR_ACTIVE:reg.IR_ACTIVE + 12] = reg.encode_joints(self.active, name="ACTIVE")
        return r
