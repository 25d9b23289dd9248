"""Links that heal: :class:`LinkWatch` keeps every peer endpoint of one SUB socket connected, whatever a
listener on its port did (see the docstring of :mod:`flexsheet.runtime.zmq`)."""

from __future__ import annotations

import logging
import struct
import time
from collections.abc import Iterable

import zmq

from flexsheet.runtime.zmq.curve import CurveConfig
from flexsheet.runtime.zmq.frames import EVENTS, NOBLOCK, POLLIN, RCVMORE

__all__ = ["LinkWatch"]

log = logging.getLogger(__name__)
_monotonic = time.monotonic

# monitor events as plain ints (pyzmq's enums cost an enum operation each)
_EV_CONNECTED, _EV_DELAYED = int(zmq.EVENT_CONNECTED), int(zmq.EVENT_CONNECT_DELAYED)
_EV_RETRIED, _EV_DISCONNECTED = int(zmq.EVENT_CONNECT_RETRIED), int(zmq.EVENT_DISCONNECTED)
_EV_OK, _EV_FAIL_NO_DETAIL = int(zmq.EVENT_HANDSHAKE_SUCCEEDED), int(zmq.EVENT_HANDSHAKE_FAILED_NO_DETAIL)
_EV_FAIL_PROTOCOL, _EV_FAIL_AUTH = (int(zmq.EVENT_HANDSHAKE_FAILED_PROTOCOL),
                                    int(zmq.EVENT_HANDSHAKE_FAILED_AUTH))
_LINK_EVENTS = (_EV_CONNECTED | _EV_DELAYED | _EV_RETRIED | _EV_DISCONNECTED | _EV_OK | _EV_FAIL_PROTOCOL
                | _EV_FAIL_AUTH | _EV_FAIL_NO_DETAIL)
_PROTOCOL_ERRORS = {int(getattr(zmq, n)): n[len("PROTOCOL_ERROR_"):].lower().replace("_", " ")
                    for n in dir(zmq) if n.startswith("PROTOCOL_ERROR_")}


class _Link:
    """What :class:`LinkWatch` knows of one peer endpoint."""

    __slots__ = ("endpoint", "up", "since", "check_at", "retry_at", "backoff", "failures", "failed_down",
                 "unlogged", "logged_at", "reason", "reconnects")

    def __init__(self, endpoint: str, now: float) -> None:
        self.endpoint = endpoint
        self.up = False
        self.since = now                      # when it last went up or down (down from the start)
        self.check_at: float | None = None    # the session must show a sign of life by then, or it is gone
        self.retry_at: float | None = None    # gone: connect again then
        self.backoff = LinkWatch.BACKOFF_MIN_S
        self.failures = 0                     # failed handshakes, in all
        self.failed_down = 0                  # ... since the link was last up
        self.unlogged = 0                     # ... since the last log line
        self.logged_at = -1e9
        self.reason = ""                      # the last failure
        self.reconnects = 0                   # connections made again by the watch


class LinkWatch:
    """Keeps every peer endpoint of one SUB socket connected, whatever a listener on that port did.

    libzmq reconnects a connection lost to a network error, but a protocol error (the peer is not ZMTP, speaks
    another security mechanism, sends a malformed greeting or command) ends the connection's session for good:
    libzmq never connects to that endpoint again. Read from the socket's monitor: a session that disconnects
    and shows no reconnect (``EVENT_CONNECT_RETRIED``, which libzmq emits right after the disconnect when it
    retries) within :data:`GRACE_S`, or that failed its handshake (``HANDSHAKE_FAILED_PROTOCOL``/``_AUTH``),
    is gone: the endpoint is disconnected and connected again after a back-off (:data:`BACKOFF_MIN_S` doubling
    to :data:`BACKOFF_MAX_S`; reset by a handshake that succeeds). So within about ``BACKOFF_MAX_S`` +
    libzmq's ``RECONNECT_IVL_MAX`` (1 s) after a squatter leaves and the real publisher is back, messages flow
    again.

    :meth:`poll` runs on the socket's thread (the transports' safety poll, every 50 ms). A connection given up
    is logged at most once per :data:`LOG_EVERY_S` per endpoint, with the count of failed handshakes;
    :meth:`report` names the endpoints without a link for more than :data:`SILENT_S` (the node's heartbeat
    says it).
    """

    GRACE_S = 0.5
    BACKOFF_MIN_S = 0.1
    BACKOFF_MAX_S = 1.0
    LOG_EVERY_S = 5.0
    SILENT_S = 5.0
    POLL_S = 0.05

    def __init__(self, sock: zmq.Socket, peers: Iterable[str], curve: CurveConfig | None = None) -> None:
        self.sock = sock
        self.curve = curve
        self.mon: zmq.Socket | None = sock.get_monitor_socket(_LINK_EVENTS)
        now = _monotonic()
        self.links: dict[str, _Link] = {ep: _Link(ep, now) for ep in peers}
        self._busy: set[_Link] = set()  # links with a pending check or retry
        self.next_poll = now

    def add(self, endpoint: str) -> None:
        """Watch one more endpoint (connected by the caller)."""
        if endpoint not in self.links:
            self.links[endpoint] = _Link(endpoint, _monotonic())

    def remove(self, endpoint: str) -> None:
        """Stop watching an endpoint (disconnected by the caller)."""
        link = self.links.pop(endpoint, None)
        if link is not None:
            self._busy.discard(link)

    def poll(self, now: float | None = None) -> None:
        """Read the monitor's events and connect again to every endpoint whose session is gone."""
        mon = self.mon
        if mon is None or mon.closed or self.sock.closed:
            return
        now = _monotonic() if now is None else now
        self.next_poll = now + self.POLL_S
        while mon.getsockopt(EVENTS) & POLLIN:
            try:
                head = mon.recv(NOBLOCK)
                endpoint = mon.recv(NOBLOCK).decode(errors="replace") if mon.getsockopt(RCVMORE) else ""
            except zmq.Again:
                break
            link = self.links.get(endpoint)
            if link is not None and len(head) >= 6:
                self._event(link, *struct.unpack_from("<HI", head), now)
        for link in list(self._busy):
            self._step(link, now)

    def _event(self, link: _Link, event: int, value: int, now: float) -> None:
        if event == _EV_RETRIED or event == _EV_DELAYED or event == _EV_CONNECTED:
            link.check_at = None                       # libzmq is (re)connecting: alive
        elif event == _EV_OK:
            if link.failed_down:
                log.info("link to %s up again (%d failed handshake(s) while it was down)", link.endpoint,
                         link.failed_down)
            link.up, link.since = True, now
            link.check_at = link.retry_at = None
            link.backoff = self.BACKOFF_MIN_S
            link.failed_down = 0
        elif event == _EV_DISCONNECTED:
            if link.up:
                link.up, link.since = False, now
            if link.check_at is None and link.retry_at is None:
                link.check_at = now + self.GRACE_S     # gone unless libzmq retries
                self._busy.add(link)
        elif event == _EV_FAIL_PROTOCOL or event == _EV_FAIL_AUTH or event == _EV_FAIL_NO_DETAIL:
            if event == _EV_FAIL_PROTOCOL:
                link.reason = "handshake refused: " + _PROTOCOL_ERRORS.get(value,
                                                                           f"protocol error {value:#x}")
            elif event == _EV_FAIL_AUTH:
                link.reason = f"handshake refused by the publisher (ZAP status {value})"
            # a refusal says more
            elif not (link.failed_down and link.reason.startswith("handshake refused")):
                link.reason = f"handshake failed: {_strerror(value)}"
            link.failures += 1
            link.failed_down += 1
            link.unlogged += 1
            if event != _EV_FAIL_NO_DETAIL and link.retry_at is None:
                link.check_at = now                    # libzmq ends the connection: no retry will come
                self._busy.add(link)

    def _step(self, link: _Link, now: float) -> None:
        if link.check_at is not None and now >= link.check_at:
            link.check_at = None
            link.retry_at = now + link.backoff
            self._log(link, now)
        if link.retry_at is not None and now >= link.retry_at:
            link.retry_at = None
            link.backoff = min(self.BACKOFF_MAX_S, link.backoff * 2.0)
            self._reconnect(link)
        if link.check_at is None and link.retry_at is None:
            self._busy.discard(link)

    def _reconnect(self, link: _Link) -> None:
        sock, ep = self.sock, link.endpoint
        try:
            sock.disconnect(ep)
        except zmq.ZMQError:
            pass  # libzmq may have dropped the endpoint already
        try:
            if self.curve is not None:
                sock.curve_serverkey = self.curve.server_keys[ep]
            sock.connect(ep)
        except (zmq.ZMQError, KeyError) as exc:
            link.retry_at = _monotonic() + link.backoff
            log.warning("link to %s: cannot connect again: %s", ep, exc)
            return
        link.reconnects += 1

    def _log(self, link: _Link, now: float) -> None:
        """One line per :data:`LOG_EVERY_S` per endpoint: the connection was given up, why, how often."""
        if now - link.logged_at < self.LOG_EVERY_S:
            return
        n, link.unlogged, link.logged_at = link.unlogged, 0, now
        log.warning("link to %s: %s; libzmq gave up on it, connecting again in %.1f s (back-off up to %.0f "
                    "s; %d failed handshake(s) since the last line, %d in all)", link.endpoint,
                    link.reason or "ended without a reconnect", link.retry_at - now, self.BACKOFF_MAX_S, n,
                    link.failures)

    def report(self, now: float | None = None) -> str:
        """``"no link to EP for N s (reason)"`` for each endpoint (at most 3 named) down for more than
        :data:`SILENT_S`, joined by "; ", or ""."""
        now = _monotonic() if now is None else now
        silent = [x for x in self.links.values() if not x.up and now - x.since > self.SILENT_S]
        if not silent:
            return ""
        parts = [f"no link to {x.endpoint} for {now - x.since:.0f} s"
                 + (f" ({x.failed_down} failed handshake(s), last: {x.reason})" if x.failed_down else "")
                 for x in silent[:3]]
        if len(silent) > 3:
            parts.append(f"and {len(silent) - 3} more endpoint(s)")
        return "; ".join(parts)

    def close(self) -> None:
        """Stop the monitor and close its socket (before the SUB socket and the context)."""
        mon, self.mon = self.mon, None
        if mon is None:
            return
        try:
            if not self.sock.closed:
                self.sock.disable_monitor()
        except zmq.ZMQError:
            pass
        mon.close(linger=0)


def _strerror(code: int) -> str:
    import os

    try:
        return os.strerror(code)
    except ValueError:
        return f"errno {code}"

