"""The controller twin's MELFA real-time external control ("MXT") server: UDP, one 196-byte packet per cycle.

:class:`MxtCore` is the controller logic (pure; time is passed in), :class:`MxtTwin` its asyncio UDP server.
Packet codec: :mod:`messages.mxt`; protocol facts and sources: ``design/mxt_protocol.md``.

Behaviour (what the twin does; where a public source does not settle a point the twin's choice is named):

* **Session.** The controller program runs ``Open "ENET:<PC-IP>" As #1 / Mxt 1,1,<filter>`` in a loop (the
  looping program of docs/arm.md). Until a NULL packet arrives the twin is *idle* (the ``Mxt`` instruction
  waits): it answers NULL packets only, and the first NULL opens a session. MOVE and END packets outside a
  session get no answer (nobody listens on port 10000 then).
* **Answers.** In a session every datagram gets one reply, sent to the datagram's source address and port,
  at the twin's **next control cycle** ("the controller takes the command in one control cycle and returns
  its state in the next", T-doc 33-36). Malformed datagrams (wrong length, unknown codes) are dropped and
  counted.
* **Commands.** MOVE with SendType JOINT (the ``Mxt 1,1`` joint mode) is latched at once; the newest
  command received before a cycle is the one executed in it (no command buffer). A MOVE is **refused**
  (not executed, counted; the reply's JOINT keeps showing the command being executed) if its SendType is
  not JOINT, a joint is not finite or outside the joint limits, or a joint's step from the command being
  executed exceeds ``qd_max · period · step_tolerance`` (the speed limit). A real controller's reaction to
  an oversize step (an error and servo off) is not public; the twin keeps the session open.
* **Monitor slots.** Each reply fills the four slots with the types the request asked for: JOINT and
  FJOINT = the command being executed once the packet was taken (its own if accepted, the previous one if
  refused; no ``Mxt`` filter is modelled), FB_JOINT = the servo model's measured joints (:mod:`.servo`) at
  the cycle that sends the reply. Types the twin does not model (POSE, PULSE, currents …) come back as
  type NULL with zero data: the reply's RecvType fields say what each slot holds.
* **Counters.** The reply echoes the request's CCount (whether a real controller echoes it is unconfirmed)
  and carries in TCount the number of control cycles without a packet since the session opened
  (saturating at 65535; meaning after the third-party "melpy" note, unconfirmed).
* **No packets.** After ``timeout`` s without a packet in a session the twin either keeps servoing to
  the last command until packets resume (``on_timeout="hold"``, TORK's choice) or faults
  (``"fault"``): the arm stops where it is, the session ends and only a new NULL packet (the operator
  resetting the error and restarting the program) opens another one.
* **END** ends the session (the reply to END is sent; whether a real controller answers END is
  unconfirmed); the arm holds the last command.
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
    step_tolerance : ≥ 1, allowed multiple of ``qd_max · period`` per commanded step.

    Raises ``ValueError`` naming the argument on bad values.
    """

    def __init__(self, q0, period: float = 0.00711, servo: ServoParams | None = None, timeout: float = 0.5,
                 on_timeout: str = "hold", step_tolerance: float = 1.5, now: float = 0.0) -> None:
        if not (period > 0.0 and math.isfinite(period)):
            raise ValueError(f"period must be > 0 s, got {period!r}")
        if on_timeout not in ("hold", "fault"):
            raise ValueError(f"on_timeout must be 'hold' or 'fault', got {on_timeout!r}")
        if not math.isfinite(timeout):
            raise ValueError(f"timeout must be finite (<= 0 disables it), got {timeout!r}")
        if not step_tolerance >= 1.0:
            raise ValueError(f"step_tolerance must be >= 1, got {step_tolerance!r}")
        self.period = float(period)
        self.timeout = float(timeout)
        self.on_timeout = on_timeout
        self.step_tolerance = float(step_tolerance)
        self.servo = JointServo(q0, servo)
        self.active = self.servo.q.copy()        # the command being executed (JOINT)
        self.session = "idle"                    # idle | open | fault
        self.t_sim = float(now)
        self.last_packet_at: float | None = None
        self.timed_out = False
        self._got_packet = False
        self.missed_cycles = 0                   # TCount: cycles without a packet in the current session
        self.received = 0
        self.unanswered = 0                      # packets outside a session (no reply)
        self.malformed = 0
        self.moves = 0
        self.refused = 0
        self.last_refusal = ""
        self.sessions = 0
        self.ends = 0
        self.timeouts = 0
        self.faults = 0
        self.command_log: list[np.ndarray] | None = None   # set to [] to record executed commands per cycle

    # ------------------------------------------------------------------ packets
    def receive(self, pkt: mxt.Packet, now: float) -> np.ndarray | None:
        """Take one decoded request at ``now``. Returns the command being executed once it was taken (6,) rad
        (the reply's JOINT), or None if the request gets no answer (see module doc)."""
        self.received += 1
        if pkt.command == mxt.CMD_NULL:
            if self.session != "open":
                self.session = "open"
                self.sessions += 1
                self.missed_cycles = 0
            self._touch(now)
            return self.active.copy()
        if self.session != "open":
            self.unanswered += 1
            return None
        self._touch(now)
        if pkt.command == mxt.CMD_END:
            self.session = "idle"
            self.ends += 1
        else:
            self._move(pkt)
        return self.active.copy()

    def _touch(self, now: float) -> None:
        self.last_packet_at = now
        self.timed_out = False
        self._got_packet = True

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
        step = np.abs(q - self.active)
        cap = p.qd_max * self.period * self.step_tolerance
        over = np.flatnonzero(step > cap)
        if over.size:
            k = int(over[0])
            return self._refuse(f"J{k + 1} step {step[k]:.6f} rad > {cap[k]:.6f} rad per cycle (speed limit)")
        self.active = q
        self.moves += 1
        return None

    def _refuse(self, why: str) -> None:
        self.refused += 1
        self.last_refusal = why

    def reply(self, req: mxt.Packet, executing: np.ndarray | None = None) -> mxt.Packet:
        """The answer to ``req``: its four monitor slots filled (see module doc), CCount echoed.
        ``executing``: the JOINT value :meth:`receive` returned for it (default: the current command)."""
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
        return mxt.Packet(req.command, req.send_type, tuple(types), tuple(data), tcount=min(self.missed_cycles, 0xFFFF),
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
        if self.session == "open":
            if not self._got_packet:
                self.missed_cycles += 1
            if (self.timeout > 0 and self.last_packet_at is not None and not self.timed_out
                    and t - self.last_packet_at > self.timeout):
                self.timed_out = True
                self.timeouts += 1
                if self.on_timeout == "fault":
                    self.session = "fault"
                    self.faults += 1
                    self.active = self.servo.q.copy()
                    log.warning("MXT twin: no packet for %.3f s: fault, arm stopped", self.timeout)
        self._got_packet = False
        self.servo.step(self.active, self.period)
        if self.command_log is not None:
            self.command_log.append(self.active.copy())

    def summary(self) -> str:
        """One diagnostics line: session state and counters."""
        return (f"mxt session {self.session}: received {self.received}, moves {self.moves}, refused {self.refused}"
                f", missed cycles {self.missed_cycles}, timeouts {self.timeouts}, unanswered {self.unanswered}"
                f", malformed {self.malformed}, ends {self.ends}")


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
        self._queue: list[tuple[mxt.Packet, object, np.ndarray]] = []
        self._task: asyncio.Task | None = None

    def _on_datagram(self, data: bytes, addr) -> None:
        try:
            pkt = mxt.Packet.decode(data)
        except ValueError as exc:
            self.core.malformed += 1
            log.debug("MXT twin: dropped datagram from %s: %s", addr, exc)
            return
        joint = self.core.receive(pkt, time.monotonic())
        if joint is not None:
            self._queue.append((pkt, addr, joint))

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
        """At ``now``: run the control cycles due (servo), then answer the requests queued before them. A
        request is answered only after at least one control cycle has executed it (a wake-up that falls
        short of the next cycle boundary answers nothing yet)."""
        if self.tick_times is not None:
            self.tick_times.append(now)
        if self.core.advance(now) == 0:
            return
        queue, self._queue = self._queue, []
        for pkt, addr, joint in queue:
            if self.transport is None:
                return
            self.transport.sendto(self.core.reply(pkt, joint).encode(), addr)
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
