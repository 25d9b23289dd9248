"""The bridge's MELFA real-time external control ("MXT") backend: one 196-byte UDP packet per controller
cycle.

Protocol facts and sources: ``design/mxt_protocol.md``; packet codec: :mod:`messages.mxt`. The controller
must be running ``Open "ENET:<this PC>" As #1 / Mxt 1,1,<filter ms>`` (docs/arm.md).

* **Open.** One UDP socket (ephemeral local port, connected to the controller's ``host:port``, default
  10000), kept across reopens: the controller's session belongs to this address and port. The first packet
  is NULL with CCount 0, asking for JOINT (slot 0) and FB_JOINT (slot 1); a reopen sends NULL with the next
  CCount (the controller drops a CCount that does not increase within its session). Its reply gives the
  command the controller is executing; the stream restarts the limiter there, so the first MOVE is one
  limited step from it (TORK ``write_first``/``read``).
* **Stream.** Each cycle one MOVE (SendType JOINT, rad, j7/j8 = 0) with CCount + 1 per packet (M, R). The
  next MOVE leaves as soon as the reply to the last one arrives (the controller replies in its next cycle,
  so its clock paces the bridge, as in TORK's read-then-write loop), but not sooner than half a cycle after
  the last send; if no reply comes within ``2 · period`` (T and M wait 2 cycles) the next packet leaves
  anyway and **repeats the last command**: when the request was lost the controller gets it now (one step),
  when only the reply was lost the controller sees one still cycle, never a double step.
* **Measured joints** are FB_JOINT from whichever monitor slot the reply says holds it (JOINT if the
  controller did not fill FB_JOINT); velocity is their difference over the cycles between two replies.
* **Refused commands.** If a reply's JOINT (the command being executed) matches neither the command of the
  packet it answers nor a later one, the controller did not take it: the stream restarts from that JOINT
  (``hold:refused``), so it never steps from a position the controller is not at.
* **Replies** are matched to packets by their echoed CCount (or, for a controller that does not echo it,
  in order). Counted: ``late`` (arrived after the next packet left), ``lost`` (no reply after 20 cycles),
  ``unmatched``, ``repeats``. After ``lost_cycles`` cycles in a row without any reply the link is declared
  lost and reopened with a NULL packet (backoff in the stream). The controller's TCount (cycles without a
  packet, unconfirmed meaning) is kept as ``controller_missed``.
* **Shutdown** sends END (M ``on_deactivate``, R ``stop()``).
* **Disabled** (``enabled: false``, first bring-up): NULL packets instead of MOVE, every cycle: the bridge
  reports the measured joints and commands nothing.

The controller state handed to the stream is a :class:`messages.registers.ControllerState` with the STATUS
bits of the register map synthesised: ENABLED and WATCHDOG_OK while replies arrive, MOVING, IN_POSITION;
``cycle`` = replies received, ``watchdog_echo`` = the reply's CCount (low 16 bits), ``active`` = JOINT.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import math
import time
from collections import OrderedDict
from collections.abc import Callable

import numpy as np

from flexsheet.arm.stream import LinkError, Verdict
from flexsheet.arm.tracking import BridgeStatus
from messages import mxt
from messages import registers as reg

__all__ = ["MxtLink"]

log = logging.getLogger(__name__)

RECV_TYPES = (mxt.TYP_JOINT, mxt.TYP_FB_JOINT, mxt.TYP_FJOINT, mxt.TYP_NULL)
MATCH_TOL = 1e-5         # rad: JOINT readback vs a sent command (float32 rounding is < 3e-7 rad)
LOST_AFTER = 20          # cycles after which an unanswered packet counts as lost


class _Protocol(asyncio.DatagramProtocol):
    def __init__(self, link: MxtLink) -> None:
        self.link = link

    def datagram_received(self, data: bytes, addr) -> None:
        self.link._on_datagram(data)

    def error_received(self, exc: Exception) -> None:   # ICMP port unreachable: nobody listens (yet)
        self.link.socket_errors += 1


class MxtLink:
    """:class:`~flexsheet.arm.stream.ControllerLink` over MXT/UDP (see module doc).

    ``host``/``port``: the controller. ``period``: its control cycle, s. ``open_timeout``: s to wait for the
    NULL packet's reply. ``lost_cycles``: cycles without any reply before the link is reopened.
    ``record``: keep per-packet send times, round trips and reaction times (benchmarks).
    """

    name = "mxt"
    rewrite_ok = False

    def __init__(self, host: str, port: int = mxt.DEFAULT_PORT, *, period: float = 0.00711,
                 open_timeout: float = 0.2, lost_cycles: int = 50, record: bool = False) -> None:
        if not period > 0:
            raise ValueError(f"period must be > 0 s, got {period!r}")
        if lost_cycles < 2:
            raise ValueError(f"lost_cycles must be >= 2, got {lost_cycles!r}")
        self.host, self.port = host, int(port)
        self.period = float(period)
        self.open_timeout = float(open_timeout)
        self.lost_cycles = int(lost_cycles)
        self.connected = False
        self.on_ready: Callable[[], None] | None = None
        self.transport: asyncio.DatagramTransport | None = None
        self.ccount = 0
        self._pending: OrderedDict[int, float] = OrderedDict()     # ccount → monotonic send time
        self._sent_cmd: OrderedDict[int, np.ndarray] = OrderedDict()  # ccount → command (last few)
        self._t_sent = 0.0
        self._last_answered = True           # the reply to the newest packet has arrived
        self._ready_at: float | None = None
        self._replies: list[tuple[mxt.Packet, int | None]] = []     # unread (reply, answered ccount)
        self._opened = False
        self._last_state: reg.ControllerState | None = None
        self._last_fb: tuple[np.ndarray, int] | None = None
        self._missing = 0
        self._check: list[tuple[mxt.Packet, int | None]] = []
        # counters
        self.sent = 0
        self.replies = 0
        self.late = 0
        self.lost = 0
        self.unmatched = 0
        self.repeats = 0
        self.refused = 0
        self.malformed = 0
        self.socket_errors = 0
        self.opens = 0
        self.ends = 0
        self.controller_missed = 0
        self.record = record
        self.send_times: list[float] = []
        self.rtts: list[float] = []
        self.reactions: list[float] = []  # s from "controller ready" (reply in) to this send; nan: fallback

    # ------------------------------------------------------------------ socket
    def _on_datagram(self, data: bytes) -> None:
        now = time.monotonic()
        try:
            pkt = mxt.Packet.decode(data)
        except ValueError:
            self.malformed += 1
            return
        self.replies += 1
        self.controller_missed = pkt.tcount
        answered = None
        if pkt.ccount in self._pending:
            answered = pkt.ccount
        elif self._pending:
            self.unmatched += 1
            answered = next(iter(self._pending))   # a controller that does not echo CCount: in order
        if answered is not None:
            t_sent = self._pending.pop(answered)
            for c in [c for c in self._pending if c < answered]:   # older ones will not be answered now
                del self._pending[c]
                self.lost += 1
            if self.record:
                self.rtts.append(now - t_sent)
            if answered == self.ccount:
                self._last_answered = True
                self._ready_at = now
            else:
                self.late += 1
        self._replies.append((pkt, answered))
        if self._last_answered and self.on_ready is not None:
            self.on_ready()

    async def _ensure_socket(self) -> None:
        if self.transport is None:
            loop = asyncio.get_running_loop()
            self.transport, _ = await loop.create_datagram_endpoint(lambda: _Protocol(self),
                                                                    remote_addr=(self.host, self.port))

    def _send_packet(self, pkt: mxt.Packet, cmd: np.ndarray | None) -> None:
        if self.transport is None:
            raise LinkError("socket closed")
        try:
            self.transport.sendto(pkt.encode())
        except (OSError, ValueError) as exc:
            raise LinkError(f"send failed: {exc}") from exc
        now = time.monotonic()
        if self.record:
            ready = self.ready_time()
            self.reactions.append(now - ready if ready is not None else math.nan)
        self.sent += 1
        self._t_sent = now
        self._pending[pkt.ccount] = now
        self._last_answered = False
        self._ready_at = None
        if cmd is not None:
            self._sent_cmd[pkt.ccount] = cmd.copy()
            while len(self._sent_cmd) > 8:
                self._sent_cmd.popitem(last=False)
        if self.record:
            self.send_times.append(now)
        while self._pending:
            c, t = next(iter(self._pending.items()))
            if now - t <= LOST_AFTER * self.period:
                break
            del self._pending[c]
            self.lost += 1

    # ------------------------------------------------------------------ ControllerLink
    async def open(self) -> bool:
        """Send NULL (CCount 0, or the next one on a reopen) and wait ``open_timeout`` for its reply. Never
        raises."""
        try:
            await self._ensure_socket()
        except OSError as exc:
            log.debug("MXT socket: %s", exc)
            return False
        if self.sent:   # a reopen: CCount goes on increasing (the session may still be ours)
            self.ccount = (self.ccount + 1) & 0xFFFFFFFF
        self._pending.clear()
        self._sent_cmd.clear()
        self._replies.clear()
        self._last_state = None
        self._last_fb = None
        self._missing = 0
        try:
            self._send_packet(mxt.null_packet(self.ccount, RECV_TYPES), None)
        except LinkError:
            return False
        t_end = time.monotonic() + self.open_timeout
        while not self._replies and time.monotonic() < t_end:
            await asyncio.sleep(min(0.002, self.period / 2))
        if not self._replies:
            return False
        self.opens += 1
        self.connected = True
        self._opened = True
        return True

    def _state(self, pkt: mxt.Packet) -> reg.ControllerState:
        joint = pkt.joints(mxt.TYP_JOINT)
        fb = pkt.joints(mxt.TYP_FB_JOINT)
        if joint is None and fb is None:
            raise LinkError("reply carries neither JOINT nor FB_JOINT")
        if fb is None:
            fb = joint
        if joint is None:
            joint = fb
        if not (np.all(np.isfinite(joint)) and np.all(np.isfinite(fb))):
            raise LinkError("reply carries non-finite joints")
        vel = np.zeros(6)
        if self._last_fb is not None:
            n = (pkt.ccount - self._last_fb[1]) & 0xFFFFFFFF
            if 0 < n < 1000:
                vel = (fb - self._last_fb[0]) / (n * self.period)
        self._last_fb = (fb, pkt.ccount)
        status = reg.ST_ENABLED | reg.ST_WATCHDOG_OK
        if float(np.max(np.abs(vel))) > 1e-4:
            status |= reg.ST_MOVING
        elif float(np.max(np.abs(fb - joint))) < 1e-4:
            status |= reg.ST_IN_POSITION
        return reg.ControllerState(status=status, fault=reg.FAULT_NONE, reject=reg.REJ_NONE,
                                   cycle=self.replies,
                                   position=fb, velocity=vel, watchdog_echo=pkt.ccount & 0xFFFF, active=joint)

    async def read(self) -> reg.ControllerState:
        """The newest reply's state; raises :class:`LinkError` after ``lost_cycles`` cycles with no reply."""
        if not self.connected:
            raise LinkError("not open")
        fresh = bool(self._replies)
        if fresh:
            self._missing = 0
            pkt, _ = self._replies[-1]
            st = self._state(pkt)
            self._check = [(p, c) for p, c in self._replies if c is not None]
            self._replies.clear()
            self._last_state = st
            return st
        self._check = []
        self._missing += 1
        if self._missing >= self.lost_cycles or self._last_state is None:
            raise LinkError(f"no MXT reply for {self._missing} cycles")
        st = self._last_state
        return reg.ControllerState(status=st.status & ~reg.ST_WATCHDOG_OK, fault=st.fault, reject=st.reject,
                                   cycle=st.cycle, position=st.position, velocity=st.velocity,
                                   watchdog_echo=st.watchdog_echo, active=st.active)

    def supervise(self, st: reg.ControllerState) -> Verdict:
        """Restart at JOINT after opening or a refused command; repeat the last command when no reply came."""
        if self._opened:
            self._opened = False
            return Verdict(True, "", st.active.copy())
        if not self._check:
            self.repeats += 1
            return Verdict(False)
        for pkt, c in self._check:
            if pkt.command != mxt.CMD_MOVE or c not in self._sent_cmd:
                continue
            joint = pkt.joints(mxt.TYP_JOINT)
            if joint is None:
                continue
            later = [cmd for k, cmd in self._sent_cmd.items() if k >= c]
            if min(float(np.max(np.abs(joint - cmd))) for cmd in later) > MATCH_TOL:
                self.refused += 1
                log.warning("MXT controller did not take command %d (executing %s); restarting there", c,
                            np.round(joint, 5))
                return Verdict(True, BridgeStatus.REFUSED, joint.copy())
        return Verdict(True)

    async def send(self, cmd: np.ndarray, rewrite: bool = False) -> bool:
        """One MOVE packet (joint type, rad). Raises :class:`LinkError` (also on a non-finite command)."""
        if rewrite:
            return False
        if not self.connected:
            raise LinkError("not open")
        self.ccount = (self.ccount + 1) & 0xFFFFFFFF
        try:
            pkt = mxt.move_packet(np.asarray(cmd, dtype=float), self.ccount, RECV_TYPES)
        except ValueError as exc:
            raise LinkError(str(exc)) from exc
        self._send_packet(pkt, np.asarray(cmd, dtype=float))
        return True

    async def keepalive(self) -> None:
        """Disabled: a NULL packet (exchange data only; the controller keeps its command)."""
        if not self.connected:
            raise LinkError("not open")
        self.ccount = (self.ccount + 1) & 0xFFFFFFFF
        self._send_packet(mxt.null_packet(self.ccount, RECV_TYPES), None)

    async def after_cycle(self) -> None:
        """Nothing: MXT has no separate command channel."""

    def ready_time(self) -> float | None:
        """When the newest packet's reply has arrived: that time, but not sooner than half a cycle after the
        packet left; else None."""
        if self._last_answered and self._ready_at is not None:
            return max(self._ready_at, self._t_sent + 0.5 * self.period)
        return None

    def next_deadline(self, deadline: float, t_start: float, period: float) -> float:
        """Fallback when no reply comes: two cycles after this send (T and M wait 2 cycles for a reply)."""
        if not self.connected:
            return deadline + period
        return self._t_sent + 2.0 * period

    async def close(self, end: bool = False) -> None:
        """Send END first when ``end`` and the session is open; close the socket."""
        if self.transport is not None:
            if end and self.connected:
                self.ccount = (self.ccount + 1) & 0xFFFFFFFF
                with contextlib.suppress(LinkError):
                    self._send_packet(mxt.end_packet(self.ccount), None)
                    self.ends += 1
            self.transport.close()
            self.transport = None
        self.connected = False

    def counters(self) -> dict:
        """Packets ``sent``, ``replies``, ``late``, ``lost``, ``unmatched``, ``repeats``, ``refused``,
        ``opens``, ``controller_missed`` (the controller's TCount) and more."""
        return {k: getattr(self, k)
                for k in ("sent", "replies", "late", "lost", "unmatched", "repeats", "refused",
                          "malformed", "socket_errors", "opens", "ends",
                          "controller_missed")}

    def summary(self) -> str:
        """One diagnostics line of the counters."""
        return "mxt " + ", ".join(f"{k} {v}" for k, v in self.counters().items())
