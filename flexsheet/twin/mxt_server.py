"""The controller twin's MELFA real-time external control ("MXT") server: UDP, one 196-byte packet per cycle.

:class:`MxtCore` is the controller logic (pure; time is passed in), :class:`MxtTwin` its asyncio UDP server.
Packet codec: :mod:`messages.mxt`; protocol facts and sources: ``design/mxt_protocol.md``.

Behaviour (what the twin does; where a public source does not settle a point the twin's choice is named):

* **Session.** The controller program runs ``Open "ENET:<PC-IP>" As #1 / Mxt 1,1,<filter>`` in a loop (the
  looping program of docs/arm.md). Until a NULL packet arrives the twin is *idle* (the ``Mxt`` instruction
  waits): it answers NULL packets only, and the first NULL opens a session. MOVE and END packets outside a
  session get no answer (nobody listens on port 10000 then).
* **Owner.** A session belongs to the address *and port* whose NULL opened it (the real controller accepts
  only the PC named in ``Open``; the twin cannot know that address, so it binds the first one). Datagrams from
  any other sender are dropped and counted (``foreign``), END included; another sender's NULL takes the
  session over only after the owner has been silent for ``owner_timeout`` s (a respawned bridge on a new
  port).
* **CCount** must increase within a session (serial-number order mod 2³²; the opening NULL may carry any
  value): a replayed or out-of-order packet is dropped unanswered and counted (``replayed``).
* **Answers.** Every datagram the session takes gets one reply, sent to the owner at the twin's **next control
  cycle** ("the controller takes the command in one control cycle and returns its state in the next", T-doc
  33-36). Malformed datagrams (wrong length, unknown codes) are dropped and counted.
* **One command per cycle.** A MOVE with SendType JOINT (the ``Mxt 1,1`` joint mode) is checked on arrival
  against the command executed in the previous cycle (not against the last packet) and, if accepted, latched;
  the cycle boundary executes the newest latched command. Earlier commands of the same cycle are dropped and
  counted (``superseded``); every packet beyond the first in a cycle counts as ``extra``. *Newest, not first*:
  the manual (not available here) gives one command per cycle with no command buffer; a one-deep receive
  register is overwritten by a later packet, and the reply of a dropped packet then shows the newer command
  it lost to, so a client sees it was not taken. However many packets arrive, the executed command moves by
  at most one checked step per cycle.
* **Refusals.** A MOVE is refused (not executed, counted; the reply's JOINT shows what is executed instead) if
  its SendType is not JOINT, a joint is not finite or outside the joint limits, or a joint's step from the
  command executed in the previous cycle exceeds ``qd_max · period · step_tolerance`` (the speed limit). A
  real controller's reaction to an oversize step (an error and servo off) is not public; the twin keeps the
  session open.
* **Monitor slots.** Each reply fills the four slots with the types the request asked for: JOINT and
  FJOINT = the command executed in the cycle that sends the reply (the packet's own if it was taken; no
  ``Mxt`` filter is modelled), FB_JOINT = the servo model's measured joints (:mod:`.servo`) at that cycle.
  Types the twin does not model (POSE, PULSE, currents …) come back as type NULL with zero data: the reply's
  RecvType fields say what each slot holds.
* **Counters.** The reply echoes the request's CCount (whether a real controller echoes it is unconfirmed)
  and carries in TCount the number of control cycles without a packet since the session opened
  (saturating at 65535; meaning after the third-party "melpy" note, unconfirmed).
* **No packets.** After ``timeout`` s without a packet in a session the twin either keeps servoing to
  the last command until packets resume (``on_timeout="hold"``, TORK's choice) or faults
  (``"fault"``): the arm stops where it is, the session ends and only a new NULL packet (the operator
  resetting the error and restarting the program) opens another one.
* **END** from the owner ends the session (the reply to END is sent; whether a real controller answers END is
  unconfirmed); the arm holds the last executed command, a command latched in the same cycle is dropped.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import math
import time

import numpy as np

from flexsheet.twin.servo import JointServo, ServoParams
from messages import mxt

__all__ = ["MxtCore", "MxtTwin"]

log = logging.getLogger(__name__)

_JOINT_LIKE = (mxt.TYP_JOINT, mxt.TYP_FJOINT)


class MxtCore:
    """MXT controller logic of one RV-1A (see module doc). Time ``now`` is monotonic seconds.

    Parameters
    ----------
    q0 : (6,) rad, initial joints.
    period : s, control cycle (0.00711 for CR750-Q/CR800-Q, 0.0035 for CR800-R/D).
    servo : :class:`ServoParams`, optional.
    timeout : s without a packet before ``on_timeout`` acts; ``<= 0`` disables (MXTTOUT = -1).
    on_timeout : "hold" or "fault".
    step_tolerance : ≥ 1, allowed multiple of ``qd_max · period`` per executed step.
    owner_timeout : s of silence from the session's owner after which another sender's NULL takes it over.

    Raises ``ValueError`` naming the argument on bad values.
    """

    def __init__(self, q0, period: float = 0.00711, servo: ServoParams | None = None, timeout: float = 0.5,
                 on_timeout: str = "hold", step_tolerance: float = 1.5, now: float = 0.0,
                 owner_timeout: float = 1.0) -> None:
        if not (period > 0.0 and math.isfinite(period)):
            raise ValueError(f"period must be > 0 s, got {period!r}")
        if on_timeout not in ("hold", "fault"):
            raise ValueError(f"on_timeout must be 'hold' or 'fault', got {on_timeout!r}")
        if not math.isfinite(timeout):
            raise ValueError(f"timeout must be finite (<= 0 disables it), got {timeout!r}")
        if not step_tolerance >= 1.0:
            raise ValueError(f"step_tolerance must be >= 1, got {step_tolerance!r}")
        if not (owner_timeout > 0.0 and math.isfinite(owner_timeout)):
            raise ValueError(f"owner_timeout must be > 0 s, got {owner_timeout!r}")
        self.period = float(period)
        self.timeout = float(timeout)
        self.on_timeout = on_timeout
        self.step_tolerance = float(step_tolerance)
        self.owner_timeout = float(owner_timeout)
        self.servo = JointServo(q0, servo)
        self.active = self.servo.q.copy()        # the command executed in the current cycle (JOINT)
        self.pending: np.ndarray | None = None   # the newest accepted MOVE, executed at the next cycle
        self.session = "idle"                    # idle | open | fault
        self.owner: object = None                # (address, port) that opened the session
        self.last_ccount: int | None = None      # CCount of the newest packet the session took
        self.t_sim = float(now)
        self.cycles = 0                          # control cycles run
        self.last_packet_at: float | None = None
        self.timed_out = False
        self._cycle_packets = 0                  # packets the session took since the last cycle boundary
        self.missed_cycles = 0                   # TCount: cycles without a packet in the current session
        self.received = 0
        self.unanswered = 0                      # packets outside a session (no reply)
        self.malformed = 0
        self.moves = 0                           # MOVEs accepted (passed the checks)
        self.executed = 0                        # cycles that took a new command
        self.superseded = 0                      # accepted MOVEs replaced by a newer one in the same cycle
        self.extra = 0                           # packets beyond the first in one cycle
        self.refused = 0
        self.replayed = 0                        # CCount not newer than the last one taken: dropped
        self.foreign = 0                         # from another sender than the session's owner: dropped
        self.takeovers = 0
        self.last_refusal = ""
        self.sessions = 0
        self.ends = 0
        self.timeouts = 0
        self.faults = 0
        self.command_log: list[np.ndarray] | None = None   # set to [] to record executed commands per cycle

    # ------------------------------------------------------------------ packets
    def command(self) -> np.ndarray:
        """The command the next cycle executes as things stand: the latched MOVE, else the current one (6,)
        rad."""
        return (self.active if self.pending is None else self.pending).copy()

    def receive(self, pkt: mxt.Packet, now: float, addr: object = None) -> np.ndarray | None:
        """Take one decoded request from ``addr`` (the sender's (address, port); None: one local client) at
        ``now``, after running the control cycles due by then. Returns :meth:`command` once it was taken, or
        None if the request gets no answer (outside a session, another sender's, a replayed CCount; see the
        module doc)."""
        self.advance(now)
        self.received += 1
        if self.session == "open" and addr != self.owner:
            silent = self.last_packet_at is None or now - self.last_packet_at > self.owner_timeout
            if not (pkt.command == mxt.CMD_NULL and silent):
                self.foreign += 1
                return None
            self.takeovers += 1
            log.warning("MXT twin: %s silent for %.2f s; session taken over by %s", self.owner,
                        self.owner_timeout, addr)
            self.session = "idle"
        if pkt.command == mxt.CMD_NULL and self.session != "open":
            self.session = "open"
            self.owner = addr
            self.sessions += 1
            self.missed_cycles = 0
            self.pending = None
            self.last_ccount = pkt.ccount
            self._cycle_packets = 0
            self._take(now)
            return self.command()
        if self.session != "open":
            self.unanswered += 1
            return None
        if not _newer(pkt.ccount, self.last_ccount):
            self.replayed += 1
            return None
        self.last_ccount = pkt.ccount
        self._take(now)
        if pkt.command == mxt.CMD_END:
            self.session = "idle"
            self.owner = None
            self.pending = None
            self.ends += 1
        elif pkt.command == mxt.CMD_MOVE:
            self._move(pkt)
        return self.command()

    def _take(self, now: float) -> None:
        if self._cycle_packets:
            self.extra += 1
        self._cycle_packets += 1
        self.last_packet_at = now
        self.timed_out = False

    def _move(self, pkt: mxt.Packet) -> None:
        try:
            q = pkt.command_joints(6)
        except ValueError as exc:
            return self._refuse(str(exc))
        p = self.servo.p
        bad = np.flatnonzero(~np.isfinite(q) | (q < p.q_lower) | (q > p.q_upper))
        if bad.size:
            k = int(bad[0])
            return self._refuse(f"J{k + 1}={q[k]!r} rad outside [{p.q_lower[k]:.4f}, {p.q_upper[k]:.4f}]")
        step = np.abs(q - self.active)           # from the command executed in the previous cycle
        cap = p.qd_max * self.period * self.step_tolerance
        over = np.flatnonzero(step > cap)
        if over.size:
            k = int(over[0])
            return self._refuse(f"J{k + 1} step {step[k]:.6f} rad > {cap[k]:.6f} rad per cycle (speed limit)")
        if self.pending is not None:
            self.superseded += 1
        self.pending = q
        self.moves += 1
        return None

    def _refuse(self, why: str) -> None:
        self.refused += 1
        self.last_refusal = why

    def reply(self, req: mxt.Packet, executing: np.ndarray | None = None) -> mxt.Packet:
        """The answer to ``req``: its four monitor slots filled (see module doc), CCount echoed.
        ``executing``: the JOINT value (default: the command executed in the current cycle)."""
        joint = self.active if executing is None else executing
        types, data = [], []
        for t in req.recv_types:
            if t in _JOINT_LIKE:
                types.append(t)
                data.append(mxt.encode_joint_data(joint))
            elif t == mxt.TYP_FB_JOINT:
                types.append(t)
                data.append(mxt.encode_joint_data(self.servo.q))
            else:
                types.append(mxt.TYP_NULL)
                data.append(bytes(40))
        return mxt.Packet(req.command, req.send_type, tuple(types), tuple(data),
                          tcount=min(self.missed_cycles, 0xFFFF),
                          ccount=req.ccount)

    # ------------------------------------------------------------------ time
    def advance(self, now: float, max_steps: int = 20) -> int:
        """Run control cycles up to ``now`` (s); returns how many ran (at most ``max_steps``; a stalled caller
        does not replay a long gap: simulated time then jumps to ``now``)."""
        n = 0
        while self.t_sim + self.period <= now and n < max_steps:
            self.t_sim += self.period
            self._cycle(self.t_sim)
            n += 1
        if self.t_sim + self.period <= now:
            self.t_sim = now
        return n

    def _cycle(self, t: float) -> None:
        self.cycles += 1
        if self.pending is not None:             # this cycle executes the newest command of the last one
            self.active, self.pending = self.pending, None
            self.executed += 1
        if self.session == "open":
            if not self._cycle_packets:
                self.missed_cycles += 1
            if (self.timeout > 0 and self.last_packet_at is not None and not self.timed_out
                    and t - self.last_packet_at > self.timeout):
                self.timed_out = True
                self.timeouts += 1
                if self.on_timeout == "fault":
                    self.session = "fault"
                    self.owner = None
                    self.faults += 1
                    self.active = self.servo.q.copy()
                    log.warning("MXT twin: no packet for %.3f s: fault, arm stopped", self.timeout)
        self._cycle_packets = 0
        self.servo.step(self.active, self.period)
        if self.command_log is not None:
            self.command_log.append(self.active.copy())

    def summary(self) -> str:
        """One diagnostics line: session state and counters."""
        return (f"mxt session {self.session} ({self.owner}): received {self.received}, moves {self.moves}, "
                f"executed {self.executed}, superseded {self.superseded}, extra {self.extra}, refused "
                f"{self.refused}, replayed {self.replayed}, foreign {self.foreign}, takeovers "
                f"{self.takeovers}, missed cycles {self.missed_cycles}, timeouts {self.timeouts}, unanswered "
                f"{self.unanswered}, malformed {self.malformed}, ends {self.ends}")


def _newer(c: int, last: int | None) -> bool:
    """Whether CCount ``c`` comes after ``last`` in serial-number order (RFC 1982, 32 bits)."""
    if last is None:
        return True
    d = (c - last) & 0xFFFFFFFF
    return 0 < d < 0x80000000


class _Protocol(asyncio.DatagramProtocol):
    def __init__(self, twin: MxtTwin) -> None:
        self.twin = twin

    def datagram_received(self, data: bytes, addr) -> None:
        self.twin._on_datagram(data, addr)

    def error_received(self, exc: Exception) -> None:   # e.g. ICMP port unreachable from a gone client
        log.debug("MXT twin: socket error %s", exc)


class MxtTwin:
    """UDP server around an :class:`MxtCore` (its clock is ``time.monotonic()``).

    ``host``/``port``: where to listen (port 0 picks a free port; :attr:`port` holds the bound one after
    :meth:`start`). A background task runs the control cycle every ``core.period`` and sends the replies.
    """

    def __init__(self, core: MxtCore, host: str = "127.0.0.1", port: int = mxt.DEFAULT_PORT) -> None:
        self.core = core
        self.host = host
        self.port = port
        self.transport: asyncio.DatagramTransport | None = None
        self.replied = 0
        self.tick_times: list[float] | None = None   # set to [] to record each wake-up (monotonic s)
        self._queue: list[tuple[mxt.Packet, object, int]] = []   # (request, sender, cycles run when taken)
        self._task: asyncio.Task | None = None

    def _on_datagram(self, data: bytes, addr) -> None:
        try:
            pkt = mxt.Packet.decode(data)
        except ValueError as exc:
            self.core.malformed += 1
            log.debug("MXT twin: dropped datagram from %s: %s", addr, exc)
            return
        joint = self.core.receive(pkt, time.monotonic(), addr)   # runs the cycles due first
        self._answer()                          # requests of a cycle that ran just now
        if joint is not None:
            self._queue.append((pkt, addr, self.core.cycles))

    async def start(self) -> int:
        """Bind the UDP socket and start the control cycle; returns the bound port."""
        loop = asyncio.get_running_loop()
        self.transport, _ = await loop.create_datagram_endpoint(lambda: _Protocol(self),
                                                                local_addr=(self.host, self.port))
        self.port = self.transport.get_extra_info("sockname")[1]
        self._task = loop.create_task(self._run())
        return self.port

    async def _run(self) -> None:
        # wake at each control-cycle boundary of the core's clock (not a separate schedule whose phase
        # could drift against it and wake just short of a boundary)
        while True:
            delay = self.core.t_sim + self.core.period - time.monotonic()
            if delay > 0:
                await asyncio.sleep(delay)
            self.cycle(time.monotonic())

    def cycle(self, now: float) -> None:
        """At ``now``: run the control cycles due (servo), then answer the requests taken before them. A
        request is answered only after a control cycle has run since it was taken (a wake-up that falls short
        of the next cycle boundary answers nothing yet); its JOINT is the command that cycle executes."""
        if self.tick_times is not None:
            self.tick_times.append(now)
        self.core.advance(now)
        self._answer()

    def _answer(self) -> None:
        n = self.core.cycles
        if not self._queue or self._queue[0][2] >= n:
            return
        due = [q for q in self._queue if q[2] < n]
        self._queue = [q for q in self._queue if q[2] >= n]
        for pkt, addr, _ in due:
            if self.transport is None:
                return
            self.transport.sendto(self.core.reply(pkt).encode(), addr)
            self.replied += 1

    async def stop(self) -> None:
        """Stop the cycle task and close the socket."""
        if self._task is not None:
            self._task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._task
            self._task = None
        if self.transport is not None:
            self.transport.close()
            self.transport = None
