"""The bridge's Modbus side: a pymodbus async TCP client that streams joint targets every period.

:class:`ArmStream` runs the cycle (default 7.1 ms, absolute deadlines so errors do not accumulate):

1. read the input registers (state, status, fault) — decoded by :mod:`.registers`;
2. if the controller is not enabled: re-seed the limiter at the measured joints (so the next command equals
   where the arm is: no jump after a reconnect, a fault or an e-stop) and, unless e-stopped, write
   COMMAND = ENABLE (with a RESET edge for a watchdog fault when ``auto_reset``);
3. step the limiter (:mod:`.interp`) toward the tracker's goal (:mod:`.tracking`) and write the watchdog
   counter + the six targets in one FC16 request (registers 1..13), stamping ``write_stamp``;
4. hand a :class:`CycleReport` to the ``on_cycle`` callback (the node publishes it).

Lost connection (timeout, reset, refused): the client is closed and a new one is tried after a backoff that
doubles from ``backoff_min`` to ``backoff_max``; meanwhile the cycle keeps its schedule and reports
``bridge_status = "disconnected"``.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from pymodbus.client import AsyncModbusTcpClient
from pymodbus.exceptions import ModbusException

from messages import registers as reg
from nodes.arm_bridge.interp import StreamLimiter
from nodes.arm_bridge.tracking import TargetTracker

__all__ = ["CycleReport", "ArmStream"]

log = logging.getLogger(__name__)


@dataclass
class CycleReport:
    """What one cycle did. Times: ``t_cycle`` monotonic s (scheduled start was ``t_deadline``),
    ``write_stamp`` wall-clock s (``time.time()``) of this cycle's target write (0 if none); in the first
    report after a new target it is the time of that target's first write (which may have been an
    immediate :meth:`ArmStream.refresh` earlier in the period). ``state``: decoded
    controller state or None when disconnected. ``commanded`` (6,) rad. ``bridge_status``: see node doc."""

    t_cycle: float
    t_deadline: float
    write_stamp: float
    state: reg.ControllerState | None
    commanded: np.ndarray
    bridge_status: str
    target_stamp: float


class ArmStream:
    """Streams one arm's joint targets to its controller over Modbus TCP.

    Parameters: ``tracker`` (goal source), ``limiter`` (command shaping, its period is the cycle period),
    ``host``/``port`` of the controller, ``device_id`` (Modbus unit id), ``request_timeout`` s,
    ``backoff_min``/``backoff_max`` s, ``auto_reset`` (reset watchdog faults automatically),
    ``on_cycle`` callback(CycleReport), ``clock`` (wall clock for stamps, default ``time.time``).
    """

    def __init__(self, tracker: TargetTracker, limiter: StreamLimiter, host: str, port: int, *,
                 device_id: int = 1, request_timeout: float = 0.1, backoff_min: float = 0.05,
                 backoff_max: float = 2.0, auto_reset: bool = True,
                 on_cycle: Callable[[CycleReport], None] | None = None, clock=time.time) -> None:
        self.tracker = tracker
        self.limiter = limiter
        self.host, self.port, self.device_id = host, int(port), int(device_id)
        self.request_timeout = float(request_timeout)
        self.backoff_min, self.backoff_max = float(backoff_min), float(backoff_max)
        self.auto_reset = auto_reset
        self.on_cycle = on_cycle
        self.clock = clock
        self.period = limiter.T
        self.client: AsyncModbusTcpClient | None = None
        self.connected = False
        self.backoff = self.backoff_min
        self.next_connect = 0.0
        self.watchdog = 0
        self.cmd_written: int | None = None
        self.state: reg.ControllerState | None = None
        self.reconnects = 0
        self.connect_failures = 0
        self.cycles = 0
        self.cycle_times: list[float] | None = None   # set to [] to record (monotonic start, deadline)
        self._seeded = False
        self._pending_cmd: int | None = None
        self._task: asyncio.Task | None = None
        self._io = asyncio.Lock()               # one read/step/write sequence at a time
        self._slot: tuple[np.ndarray, np.ndarray] | None = None   # limiter (c, v) before this period's step
        self._slot_target = 0.0                 # source stamp of the goal this period's command was made for
        self._slot_deadline = 0.0               # monotonic end of the current period
        self._first_write: tuple[float, float] = (0.0, 0.0)      # (source stamp, time of its first write)
        self._first_reported = True
        self.refreshes = 0

    # ------------------------------------------------------------------ connection
    async def _connect(self) -> bool:
        self._close()
        client = AsyncModbusTcpClient(self.host, port=self.port, timeout=self.request_timeout, retries=0,
                                      reconnect_delay=0, reconnect_delay_max=0)
        try:
            ok = await asyncio.wait_for(client.connect(), timeout=max(0.2, 2 * self.request_timeout))
        except (TimeoutError, OSError, ModbusException):
            ok = False
        if not ok:
            client.close()
            return False
        self.client = client
        self.connected = True
        self.cmd_written = None
        self._seeded = False
        return True

    def _close(self) -> None:
        if self.client is not None:
            with contextlib.suppress(Exception):
                self.client.close()
        self.client = None
        self.connected = False

    def _lost(self, why: str) -> None:
        if self.connected:
            log.warning("arm controller %s:%d lost (%s); reconnecting with backoff", self.host, self.port, why)
        self._close()
        self.state = None
        self.next_connect = time.monotonic() + self.backoff
        self.backoff = min(self.backoff_max, self.backoff * 2.0)

    # ------------------------------------------------------------------ one cycle
    async def cycle(self, t_deadline: float) -> CycleReport:
        """Run one cycle (see module doc); never raises on network errors."""
        async with self._io:
            return await self._cycle(t_deadline)

    async def refresh(self) -> bool:
        """A new target arrived mid-period: redo this period's step toward it and write it now.

        The limiter is rolled back to its state before this period's step and stepped again, so the
        command stream still moves by one period's worth of motion (no limit is exceeded), but the target
        reaches the controller without waiting for the next tick (the controller latches the registers at
        its own period). Returns True if a write was made. Never raises on network errors.
        """
        async with self._io:
            if (not self.connected or self.client is None or self._slot is None or self.state is None
                    or self.tracker.source_stamp == self._slot_target or time.monotonic() >= self._slot_deadline
                    or not self.state.has(reg.ST_ENABLED) or self.state.fault):
                return False
            c, v = self._slot
            self.limiter.c, self.limiter.v = c.copy(), v.copy()
            cmd = self.limiter.step(self.tracker.goal_for(self.clock(), self.limiter.c))
            self._slot_target = self.tracker.source_stamp
            stamp = self.clock()
            try:
                wr = await self.client.write_registers(reg.HR_WATCHDOG, [self.watchdog, *reg.encode_joints(cmd)],
                                                       device_id=self.device_id)
            except (TimeoutError, ModbusException, OSError, ValueError) as exc:
                self._lost(type(exc).__name__)
                return False
            if wr.isError():
                return False
            self._note_write(stamp)
            self.refreshes += 1
            return True

    def _note_write(self, stamp: float) -> None:
        if self._first_write[0] != self.tracker.source_stamp:
            self._first_write = (self.tracker.source_stamp, stamp)
            self._first_reported = False

    async def _cycle(self, t_deadline: float) -> CycleReport:
        t0 = time.monotonic()
        self._slot_deadline = t_deadline + self.period
        self.cycles += 1
        write_stamp = 0.0
        if not self.connected:
            if t0 >= self.next_connect:
                if await self._connect():
                    self.reconnects += 1
                    self.backoff = self.backoff_min
                    log.info("arm controller %s:%d connected", self.host, self.port)
                else:
                    self.connect_failures += 1
                    self._lost("connect failed")
            if not self.connected:
                return self._report(t0, t_deadline, 0.0, "disconnected")
        try:
            rr = await self.client.read_input_registers(0, count=reg.IR_COUNT, device_id=self.device_id)
            if rr.isError():
                raise ModbusException(f"read refused: {rr}")
            st = reg.decode_input(rr.registers)
            self.state = st
            status = self._supervise(st)
            if st.has(reg.ST_ENABLED) and not status.startswith("fault:"):
                self._slot = (self.limiter.c.copy(), self.limiter.v.copy())
                self._slot_target = self.tracker.source_stamp
                goal = self.tracker.goal_for(self.clock(), self.limiter.c)
                cmd = self.limiter.step(goal)
            else:
                self._slot = None
                cmd = self.limiter.c.copy()
            self.watchdog = (self.watchdog + 1) & 0xFFFF
            write_stamp = self.clock()   # the request leaves now (the reply only confirms it)
            wr = await self.client.write_registers(reg.HR_WATCHDOG, [self.watchdog, *reg.encode_joints(cmd)],
                                                   device_id=self.device_id)
            self._note_write(write_stamp)
            if wr.isError():
                # refused by the controller (should not happen: the limiter respects its checks); re-seed
                log.warning("controller refused targets: %s", wr)
                self.limiter.reset(st.position)
                status = "hold:refused"
        except (TimeoutError, ModbusException, OSError, ValueError) as exc:
            self._lost(type(exc).__name__)
            return self._report(t0, t_deadline, 0.0, "disconnected")
        return self._report(t0, t_deadline, write_stamp, status)

    def _supervise(self, st: reg.ControllerState) -> str:
        """Decide the bridge status from the controller state; write COMMAND when needed (queued)."""
        if not self._seeded:
            self.limiter.reset(st.position)
            self.tracker.seed(st.position)
            self._seeded = True
        if st.fault == reg.FAULT_ESTOP or st.has(reg.ST_ESTOP):
            self.limiter.reset(st.position)
            return "fault:estop"
        if st.fault == reg.FAULT_WATCHDOG:
            self.limiter.reset(st.position)
            if self.auto_reset:
                self._pending_cmd = reg.CMD_RESET | reg.CMD_ENABLE
            return "fault:watchdog"
        if not st.has(reg.ST_ENABLED):
            self.limiter.reset(st.position)
            self._pending_cmd = reg.CMD_ENABLE
            return "hold:disabled"
        return self.tracker.status(self.clock())

    async def _write_command(self) -> None:
        cmd = self._pending_cmd
        if cmd is None and self.cmd_written is not None and self.cmd_written & reg.CMD_RESET:
            cmd = reg.CMD_ENABLE   # drop the RESET bit so the next reset is an edge again
        if cmd is None:
            return
        if cmd & reg.CMD_RESET and self.cmd_written is not None and self.cmd_written & reg.CMD_RESET:
            cmd = cmd & ~reg.CMD_RESET   # RESET acts on its rising edge: clear it now, set it next cycle
        else:
            self._pending_cmd = None
        rr = await self.client.write_register(reg.HR_COMMAND, cmd, device_id=self.device_id)
        if rr.isError():
            raise ModbusException(f"command refused: {rr}")
        self.cmd_written = cmd

    def _report(self, t0: float, t_deadline: float, write_stamp: float, status: str) -> CycleReport:
        if self.cycle_times is not None:
            self.cycle_times.append(t0)
        if write_stamp and self._first_write[0] == self.tracker.source_stamp and not self._first_reported:
            write_stamp = self._first_write[1]   # the first report of a target carries its first write
            self._first_reported = True
        rep = CycleReport(t0, t_deadline, write_stamp, self.state, self.limiter.c.copy(), status,
                          self.tracker.source_stamp)
        if self.on_cycle is not None:
            self.on_cycle(rep)
        return rep

    # ------------------------------------------------------------------ loop
    async def run(self, n_cycles: int | None = None) -> None:
        """Cycle every ``period`` on absolute deadlines (an overrun restarts the schedule, no burst)."""
        nxt = time.monotonic()
        done = 0
        while n_cycles is None or done < n_cycles:
            delay = nxt - time.monotonic()
            if delay > 0:
                await asyncio.sleep(delay)
            elif delay < -self.period:
                nxt = time.monotonic()
            await self.cycle(nxt)
            async with self._io:   # never two requests in flight on one client (refresh() writes too)
                if self.connected and self.client is not None:
                    try:
                        await self._write_command()
                    except (TimeoutError, ModbusException, OSError) as exc:
                        self._lost(type(exc).__name__)
            nxt += self.period
            done += 1

    def start(self) -> asyncio.Task:
        """Run :meth:`run` forever as a task on the current loop."""
        self._task = asyncio.get_running_loop().create_task(self.run())
        return self._task

    async def stop(self) -> None:
        """Cancel the loop task and close the connection."""
        if self._task is not None:
            self._task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._task
            self._task = None
        self._close()
