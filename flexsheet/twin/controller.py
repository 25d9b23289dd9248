"""The arm controller twin's logic, independent of Modbus transport (pure; time is passed in).

:class:`ControllerCore` owns the register image of docs/register_map.md, validates every write (a refused
write changes nothing and records a reject code), runs the joint servo (:mod:`.servo`) in fixed periods, and
implements the watchdog, the e-stop and the resets. Holding means the executed command is frozen at the joints
measured when the hold began; the servo brakes to it under its acceleration limit.

* **One command per cycle.** An accepted target write is latched, not executed: at the next cycle boundary
  the newest target latched in that period becomes the executed command (ACTIVE); targets it replaced are
  dropped and counted (``superseded``). The command executed in cycle k+1 therefore differs from the one of
  cycle k by at most one checked step, however many writes arrive in between.
* **Write checks** (as a real-time external-control controller, which refuses a too-large step rather than
  executing it): targets inside the joint limits, and while enabled each joint's step from the command
  executed in the previous cycle (ACTIVE, not the last accepted write) ≤ ``qd_max · period · step_tolerance``.
* **Watchdog**: counter unchanged for more than ``watchdog_periods`` periods while enabled → hold and
  ``FAULT_WATCHDOG``, latched until a 0→1 edge of COMMAND.RESET (writing targets or the counter again does not
  clear it).
* **E-stop**: COMMAND.STOP → hold and ``FAULT_ESTOP``, latched until :meth:`ControllerCore.local_reset` (the
  operator at the controller); a RESET over the network never clears it.
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
        self.active = self.servo.q.copy()       # the command executed in the current cycle (ACTIVE)
        self.pending: np.ndarray | None = None  # the newest accepted target, executed at the next cycle
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
        self.superseded = 0  # accepted targets replaced in the same period (never executed)
        self.executed = 0                       # cycles that took a new target
        self.network_resets_refused = 0         # RESET edges over the network while e-stopped
        self.local_resets = 0
        self.target_log: list[np.ndarray] | None = None   # set to [] to record accepted targets (tests)
        self.command_log: list[np.ndarray] | None = None  # set to [] to record the executed command per cycle

    # ------------------------------------------------------------------ writes
    def write_holding(self, address: int, values: Sequence[int], now: float) -> None:
        """Apply a write of ``values`` at holding ``address``; raise :class:`WriteRejected` and change nothing
        if any register is malformed, the command has undefined bits, a target pair is split, or a target is
        out of limits / too large a step."""
        if all(type(v) is int and 0 <= v <= 0xFFFF for v in values):   # the usual write: plain registers
            vals = list(values)
        else:
            try:
                vals = [reg.check_register(f"HR[{address + i}]", v) for i, v in enumerate(values)]
            except ValueError as e:
                self._reject(reg.REJ_ADDRESS, str(e))
        end = address + len(vals)
        if address < 0 or end > reg.HR_COUNT or not vals:
            self._reject(reg.REJ_ADDRESS, f"write {address}..{end - 1} outside holding registers "
                                          f"0..{reg.HR_COUNT - 1}")
        new = list(self.holding)
        new[address:end] = vals
        t_lo, t_hi = reg.HR_TARGET, reg.HR_TARGET + 12
        touches_targets = address < t_hi and end > t_lo
        if touches_targets and ((max(address, t_lo) - t_lo) % 2 or (min(end, t_hi) - t_lo) % 2):
            self._reject(reg.REJ_PARTIAL_PAIR, f"write {address}..{end - 1} splits a 32-bit joint target "
                                               "pair")
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
                step = np.abs(target - self.active)     # from the command executed in the previous cycle
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
            if self.pending is not None:
                self.superseded += 1
            self.pending = target
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
            if self.fault == reg.FAULT_ESTOP:
                self.network_resets_refused += 1     # only the local reset clears an e-stop
            else:
                self.fault = reg.FAULT_NONE
                self.reject = reg.REJ_NONE
                self.wd_changed_at = now
        if cmd & reg.CMD_ENABLE and self.fault == reg.FAULT_NONE:
            if not self.enabled:
                self.enabled = True
                self.active = self.servo.q.copy()
                self.pending = None
                self.wd_changed_at = now
        elif self.enabled:
            self._hold()

    def _hold(self) -> None:
        self.enabled = False
        self.active = self.servo.q.copy()
        self.pending = None

    def local_reset(self, now: float) -> bool:
        """The operator's reset at the controller (not reachable over Modbus): clear a latched e-stop or
        watchdog fault and the COMMAND register (STOP bit included). The arm stays held until a client writes
        ENABLE. Returns True if a fault was cleared."""
        had = self.fault != reg.FAULT_NONE
        self.advance(now)
        self.fault = reg.FAULT_NONE
        self.reject = reg.REJ_NONE
        self.holding[reg.HR_COMMAND] = 0
        self._hold()
        self.wd_changed_at = now
        self.local_resets += 1
        return had

    # ------------------------------------------------------------------ time
    def advance(self, now: float, max_steps: int = 20) -> int:
        """Run servo periods up to time ``now`` (s, same clock as the writes); returns the periods run.

        At most ``max_steps`` periods are run per call (a stalled caller does not replay a long gap: the
        simulated time jumps to ``now``). The watchdog is checked each period; the first period run takes the
        latched target, if any.
        """
        n = 0
        while self.t_sim + self.period <= now and n < max_steps:
            self.t_sim += self.period
            self._watchdog(self.t_sim)
            if self.pending is not None:        # this cycle executes the newest target of the last period
                self.active, self.pending = self.pending, None
                self.executed += 1
            self.servo.step(self.active, self.period)
            if self.command_log is not None:
                self.command_log.append(self.active.copy())
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
    def summary(self) -> str:
        """One diagnostics line: state and counters."""
        return (f"modbus {'enabled' if self.enabled else 'held'}, fault {self.fault}: writes {self.writes}, "
                f"rejected {self.rejections}, superseded {self.superseded}, executed {self.executed}, "
                f"network resets refused (e-stop) {self.network_resets_refused}, local resets "
                f"{self.local_resets}")

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
