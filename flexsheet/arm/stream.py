"""The bridge's streaming loop, independent of the controller protocol, and the small interface a protocol
backend implements (:class:`ControllerLink`): Modbus TCP (:mod:`.modbus_link`) or MELFA real-time external
control over UDP (:mod:`.mxt_link`).

:class:`ArmStream` runs the cycle (one per controller cycle, default 7.1 ms):

1. if the link is down, open it (after a backoff that doubles from ``backoff_min`` to ``backoff_max``);
2. ``link.read()``: this cycle's controller state (measured joints, the command being executed, status);
3. ``link.supervise(state)``: may the stream advance this cycle, does the limiter restart from some joints
   (after a (re)connect, a fault, a refused command: so the next command equals what the controller is
   executing and nothing jumps), and a hold/fault status if any;
4. step the limiter (:mod:`.interp`) one period toward the tracker's goal (:mod:`.tracking`), or repeat
   the last command when the link says not to advance, and ``link.send(cmd)`` (``write_stamp``);
5. hand a :class:`CycleReport` to ``on_cycle`` (the node publishes it); ``link.after_cycle()``.

The loop is the only writer. A new target mid-period (:meth:`ArmStream.refresh`) only marks the period
dirty and wakes the loop; the loop then, before anything else (a due cycle's read included), redoes this
period's step toward the new goal from the limiter's snapshot (so one period's motion is still one period's
step) and sends it, when the link allows a second write per period (Modbus: yes; MXT: no, exactly one packet
per controller cycle).

Pacing: on absolute deadlines ``period`` apart (an overrun restarts the schedule, no burst), or earlier when
the link says the controller is ready for the next command (:meth:`ControllerLink.ready_time`: MXT sends its
next packet when the reply to the last one arrives, so the controller's clock paces the stream).
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from flexsheet.arm.limiter import StreamLimiter
from flexsheet.arm.tracking import BridgeStatus, TargetTracker
from messages import registers as reg

__all__ = ["CycleReport", "Verdict", "LinkError", "ControllerLink", "ArmStream"]

log = logging.getLogger(__name__)


class LinkError(Exception):
    """The controller link failed (timeout, reset, refused, no replies): the stream closes it and reopens
    it."""


@dataclass(frozen=True)
class Verdict:
    """A link's reading of one controller state.

    ``advance``: the limiter may step this cycle (else the last command is repeated). ``status``: a
    hold/fault status to report instead of the tracker's ("" = none). ``reseed``: (6,) rad joints to restart
    the limiter (at rest) and seed the tracker from, or None.
    """

    advance: bool
    status: str = ""
    reseed: np.ndarray | None = None


class ControllerLink(Protocol):
    """What :class:`ArmStream` needs from a protocol backend. Errors are raised as :class:`LinkError`."""

    name: str               #: "modbus" | "mxt"
    connected: bool
    rewrite_ok: bool        #: may a second command be sent within one period (a refresh)?
    on_ready: Callable[[], None] | None   #: set by the stream: call when :meth:`ready_time` may have changed

    async def open(self) -> bool:
        """(Re)connect / open the session; True when the next :meth:`read` has a state. Never raises."""

    async def read(self) -> reg.ControllerState:
        """This cycle's controller state (SI units, see :class:`messages.registers.ControllerState`)."""

    def supervise(self, state: reg.ControllerState) -> Verdict:
        """Interpret ``state`` (see :class:`Verdict`); may queue protocol commands for :meth:`after_cycle`."""

    async def send(self, cmd: np.ndarray, rewrite: bool = False) -> bool:
        """Send joint command (6,) rad; False if the controller refused it at once (Modbus exception)."""

    async def keepalive(self) -> None:
        """Disabled stream: exchange state without commanding anything (MXT: a NULL packet; Modbus:
        nothing)."""

    async def after_cycle(self) -> None:
        """Protocol housekeeping after the cycle was reported (Modbus: the COMMAND write)."""

    def ready_time(self) -> float | None:
        """Monotonic time from which the controller takes the next command, if known before the deadline
        (MXT: the reply to the last packet arrived); None: wait for the deadline."""

    def next_deadline(self, deadline: float, t_start: float, period: float) -> float:
        """Deadline of the next cycle given this one's ``deadline`` and actual start ``t_start``."""

    async def close(self, end: bool = False) -> None:
        """Drop the connection; ``end``: also end the controller session (MXT END) on shutdown."""

    def counters(self) -> dict:
        """Diagnostics counters (ints/floats) of the link."""


@dataclass
class CycleReport:
    """What one cycle did. Times: ``t_cycle`` monotonic s (scheduled start was ``t_deadline``),
    ``write_stamp`` wall-clock s (``time.time()``) of this cycle's command send (0 if none); in the first
    report after a new target it is the time of that target's first send (which may have been a rewrite
    earlier in the period). ``state``: decoded controller state or None when disconnected. ``commanded`` (6,)
    rad. ``bridge_status``: see the node doc."""

    t_cycle: float
    t_deadline: float
    write_stamp: float
    state: reg.ControllerState | None
    commanded: np.ndarray
    bridge_status: str
    target_stamp: float


class ArmStream:
    """Streams one arm's joint commands to its controller through a :class:`ControllerLink`.

    Parameters: ``tracker`` (goal source), ``limiter`` (command shaping; its period is the cycle period),
    ``link`` (the protocol backend), ``backoff_min``/``backoff_max`` s (reopen delays), ``on_cycle``
    callback(CycleReport), ``clock`` (wall clock for stamps, default ``time.time``), ``monotonic`` (interval
    clock of the reconnect backoff and the cycle times, default ``time.monotonic``; a simulated clock's time
    when :meth:`cycle` is driven by its timers instead of :meth:`run`). ``enabled=False``: the
    stream reads the controller every cycle and commands nothing (``hold:disabled``; first bring-up).
    """

    def __init__(self, tracker: TargetTracker, limiter: StreamLimiter, link: ControllerLink, *,
                 backoff_min: float = 0.05, backoff_max: float = 2.0,
                 on_cycle: Callable[[CycleReport], None] | None = None, clock=time.time,
                 enabled: bool = True, monotonic: Callable[[], float] = time.monotonic) -> None:
        self.tracker = tracker
        self.limiter = limiter
        self.link = link
        self.backoff_min, self.backoff_max = float(backoff_min), float(backoff_max)
        self.on_cycle = on_cycle
        self.clock = clock
        self.monotonic = monotonic
        self.enabled = enabled
        self.period = limiter.T
        self.backoff = self.backoff_min
        self.next_connect = 0.0
        self.state: reg.ControllerState | None = None
        self.reconnects = 0
        self.connect_failures = 0
        self.cycles = 0
        self.refreshes = 0
        self.cycle_times: list[float] | None = None   # set to [] to record each cycle's monotonic start
        self._task: asyncio.Task | None = None
        self._stopping = False                  # set by stop(): the loop ends at its next turn
        self._waiter: asyncio.Future | None = None
        self._dirty = False
        self._snap: tuple[np.ndarray, np.ndarray] | None = None   # limiter state before this period's step
        self._snap_target = 0.0                 # source stamp of the goal this period's command was made for
        self._first_write: tuple[float, float] = (0.0, 0.0)      # (source stamp, time of its first send)
        self._first_reported = True
        link.on_ready = self._wakeup

    @property
    def connected(self) -> bool:
        """True while the link is up."""
        return self.link.connected

    # ------------------------------------------------------------------ connection
    def _lost(self, why: str) -> None:
        if self.link.connected:
            log.warning("arm controller (%s) lost (%s); reopening with backoff", self.link.name, why)
        self.link.connected = False
        self.state = None
        self._snap = None
        self.next_connect = self.monotonic() + self.backoff
        self.backoff = min(self.backoff_max, self.backoff * 2.0)

    # ------------------------------------------------------------------ one cycle
    async def cycle(self, t_deadline: float) -> CycleReport:
        """Run one cycle (see module doc); never raises on link errors."""
        return await self._cycle(t_deadline)

    async def refresh(self) -> bool:
        """A new target arrived mid-period: mark the period dirty and wake the loop, which redoes this
        period's step toward it and sends it now (links with ``rewrite_ok`` only). True if marked."""
        if (not self.link.rewrite_ok or self._snap is None or self.state is None
                or self.tracker.source_stamp == self._snap_target):
            return False
        self._dirty = True
        self._wakeup()
        return True

    def _note_write(self, stamp: float) -> None:
        if self._first_write[0] != self.tracker.source_stamp:
            self._first_write = (self.tracker.source_stamp, stamp)
            self._first_reported = False

    def _next_command(self) -> np.ndarray:
        """This period's command (6,) rad: the limiter's step toward the tracker's reference, unless that step
        would leave the clamp, braking from there, further outside its span band
        (:meth:`TargetTracker.span_worse`: the partner lags, or the joints' own paths swing the clamp); then
        the limiter brakes where it is."""
        lim = self.limiter
        before = lim.snapshot()
        now = self.clock()
        cmd = lim.step(*self.tracker.reference(now, lim.c))
        # judged where the clamp would come to rest if it braked from here (v²/2a per joint), so that it stops
        # at the band's edge rather than a braking distance past it (or, with both arms on the sheet's motion,
        # the step's end against the partner's place on it: TargetTracker.span_worse)
        if self.tracker.span_worse(before[0], cmd, cmd + lim.v * np.abs(lim.v) / (2.0 * lim.qdd_max),
                                   now + self.period):
            lim.restore(before)
            cmd = lim.step(before[0])
        return cmd

    async def _rewrite(self) -> None:
        """Redo this period's step toward the newest goal and send it (the refresh path of the loop)."""
        self._dirty = False
        if self._snap is None or not self.link.connected or self.tracker.source_stamp == self._snap_target:
            return
        self.limiter.restore(self._snap)
        cmd = self._next_command()
        self._snap_target = self.tracker.source_stamp
        stamp = self.clock()
        try:
            ok = await self.link.send(cmd, rewrite=True)
        except LinkError as exc:
            self._lost(str(exc))
            return
        if ok:
            self._note_write(stamp)
            self.refreshes += 1

    async def rewrite_now(self) -> bool:
        """For a driver without :meth:`run` (a simulated clock): after :meth:`refresh` marked the period
        dirty, redo this period's step toward the new goal and send it now. True if it was sent."""
        if not self._dirty:
            return False
        n = self.refreshes
        await self._rewrite()
        return self.refreshes > n

    async def step(self, t_deadline: float) -> CycleReport:
        """One cycle and the link's housekeeping after it (:meth:`run`'s body; a simulated clock's timer calls
        it directly). Never raises on link errors."""
        rep = await self._cycle(t_deadline)
        if self.link.connected:
            try:
                await self.link.after_cycle()
            except LinkError as exc:
                self._lost(str(exc))
        return rep

    async def _cycle(self, t_deadline: float) -> CycleReport:
        t0 = self.monotonic()
        self.cycles += 1
        self._dirty = False
        link = self.link
        if not link.connected:
            if t0 >= self.next_connect:
                if await link.open():
                    self.reconnects += 1
                    self.backoff = self.backoff_min
                    log.info("arm controller (%s) connected", link.name)
                else:
                    self.connect_failures += 1
                    self._lost("open failed")
            if not link.connected:
                return self._report(t0, t_deadline, 0.0, "disconnected")
        try:
            st = await link.read()
            self.state = st
            if not self.enabled:
                self.limiter.reset(st.position)
                self.tracker.seed(st.position)
                await link.keepalive()
                return self._report(t0, t_deadline, 0.0, BridgeStatus.DISABLED)
            verdict = link.supervise(st)
            if verdict.reseed is not None:
                self.limiter.reset(verdict.reseed)
                self.tracker.seed(verdict.reseed)
            status = verdict.status or self.tracker.status(self.clock())
            if verdict.advance:
                self._snap = self.limiter.snapshot()
                self._snap_target = self.tracker.source_stamp
                cmd = self._next_command()
                if status == BridgeStatus.OK and self.tracker.span.waiting:
                    status = BridgeStatus.SPAN_WAIT
            else:
                self._snap = None
                cmd = self.limiter.c.copy()
            write_stamp = self.clock()   # the command leaves now (a reply only confirms it)
            ok = await link.send(cmd)
            self._note_write(write_stamp)
            if not ok:
                # refused by the controller (should not happen: the limiter respects its checks): restart
                # from the measured joints
                log.warning("controller refused the command; restarting the stream from the measured joints")
                self.limiter.reset(st.position)
                self._snap = None
                status = BridgeStatus.REFUSED
        except LinkError as exc:
            self._lost(str(exc))
            return self._report(t0, t_deadline, 0.0, "disconnected")
        return self._report(t0, t_deadline, write_stamp, status)

    def _report(self, t0: float, t_deadline: float, write_stamp: float, status: str) -> CycleReport:
        if self.cycle_times is not None:
            self.cycle_times.append(t0)
        if write_stamp and self._first_write[0] == self.tracker.source_stamp and not self._first_reported:
            write_stamp = self._first_write[1]   # the first report of a target carries its first send
            self._first_reported = True
        rep = CycleReport(t0, t_deadline, write_stamp, self.state, self.limiter.c.copy(), status,
                          self.tracker.source_stamp)
        if self.on_cycle is not None:
            self.on_cycle(rep)
        return rep

    # ------------------------------------------------------------------ loop
    def _wakeup(self) -> None:
        if self._waiter is not None and not self._waiter.done():
            self._waiter.set_result(None)

    async def _wait(self, deadline: float) -> None:
        """Sleep until ``deadline`` or until woken (a refresh, or the link's ready time changed). A plain
        future + ``call_later`` (not ``asyncio.wait_for``, which can swallow a cancellation in a race)."""
        delay = deadline - time.monotonic()
        if delay <= 0:
            return
        loop = asyncio.get_running_loop()
        self._waiter = loop.create_future()
        handle = loop.call_later(delay, self._wakeup)
        try:
            await self._waiter
        finally:
            handle.cancel()
            self._waiter = None

    async def run(self, n_cycles: int | None = None) -> None:
        """Cycle until cancelled (or ``n_cycles`` cycles): see the module doc for the pacing."""
        nxt = time.monotonic()
        done = 0
        while (n_cycles is None or done < n_cycles) and not self._stopping:
            ready = self.link.ready_time() if self.link.connected else None
            due = nxt if ready is None else min(nxt, ready)
            now = time.monotonic()
            if self._dirty:
                # a new goal: its command leaves now, before this period's read (due or not), so that a loop
                # busy with other handlers does not hold it for a read's round trip
                await self._rewrite()
                continue
            if now < due:
                await self._wait(due)
                continue
            self._dirty = False
            if now - due > self.period:
                due = now   # overrun: restart the schedule rather than burst to catch up
            await self.step(due)
            nxt = self.link.next_deadline(due, time.monotonic(), self.period)
            done += 1

    def start(self) -> asyncio.Task:
        """Run :meth:`run` forever as a task on the current loop."""
        self._stopping = False
        self._task = asyncio.get_running_loop().create_task(self.run())
        return self._task

    async def stop(self, end: bool = True) -> None:
        """End the loop task and close the link (``end``: end the controller session, e.g. MXT END). An error
        the loop ended with is logged, not raised (stop is teardown); the link is closed even when stop itself
        is cancelled.

        The task is cancelled, and cancelled again every 50 ms until it has ended, and the loop also checks a
        stop flag: a single cancellation can be lost. Python 3.11's ``asyncio.wait_for`` (used inside pymodbus
        for every request) returns the reply instead of raising ``CancelledError`` when the reply and the
        cancellation arrive together (CPython gh-86296), and the loop then ran on, so stop never returned."""
        task, self._task = self._task, None
        try:
            if task is not None:
                self._stopping = True
                self._wakeup()
                while not task.done():
                    task.cancel()
                    await asyncio.wait({task}, timeout=0.05)
                self._stopping = False      # the loop has ended: a later run() or start() runs
                if not task.cancelled() and task.exception() is not None:
                    log.warning("arm stream loop ended with %r", task.exception())
        finally:
            if task is not None and not task.done():
                task.cancel()               # stop() itself was cancelled: leave no loop running
            await self.link.close(end=end)
