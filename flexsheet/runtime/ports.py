"""Local TCP ports for graphs on one machine: the ephemeral range, and free ports below it.

A node's port must lie outside the machine's ephemeral (source) port range: while the node is down its
subscribers keep reconnecting to that port, and a reconnect from the same machine can be given that very port
as its own source port and connect to itself (a TCP self-connect); the respawned node then cannot bind
("Address already in use"). Seen in CI (a renderer used all its restarts on it) and reproduced here: 8 ZeroMQ
subscribers reconnecting to a dead port 38810 took it within 4 s; at 25010 it stayed free (docs/deploy.md).
"""

from __future__ import annotations

import random
import socket
from pathlib import Path

from flexsheet.runtime.domain import DOMAIN_STRIDE, domain_id

__all__ = ["EPHEMERAL_RANGE_FILE", "LOW_PORT", "ephemeral_port_range", "free_port"]

EPHEMERAL_RANGE_FILE = Path("/proc/sys/net/ipv4/ip_local_port_range")
LOW_PORT = 20000        #: free ports are drawn from [LOW_PORT, start of the ephemeral range)


def ephemeral_port_range(path: Path = EPHEMERAL_RANGE_FILE) -> tuple[int, int]:
    """This machine's ephemeral (source) TCP port range, inclusive: Linux's ``net.ipv4.ip_local_port_range``,
    or Linux's default (32768, 60999) where that file cannot be read (another OS). Source: ip-sysctl(7)."""
    try:
        lo, hi = (int(v) for v in path.read_text().split())
        return lo, hi
    except (OSError, ValueError):
        return 32768, 60999


def free_port(span: int = 1, host: str = "127.0.0.1") -> int:
    """A TCP port on ``host`` that is free right now, with the ``span - 1`` ports above it, all outside
    :func:`ephemeral_port_range` (see the module doc for why), also once a launch file in this process's
    domain moves it (:mod:`flexsheet.runtime.domain`): in [:data:`LOW_PORT`, start of the range − the domain's
    shift), or, where the range starts too low for that, above its end. Another process may take it before the
    caller binds it. Raises ``ValueError`` on ``span`` < 1 and ``RuntimeError`` when the range leaves no room
    on either side, or no free block is found in 500 random tries."""
    if not (isinstance(span, int) and span >= 1):
        raise ValueError(f"span must be an int >= 1, got {span!r}")
    lo, hi = ephemeral_port_range()
    lo = min(lo, 32768) - DOMAIN_STRIDE * domain_id()     # a launch file written with it moves by its domain
    if lo - span > LOW_PORT:
        first, last = LOW_PORT, lo - span              # ports first .. last - 1 start a block
    elif 65536 - span > hi + 1:
        first, last = hi + 1, 65536 - span
    else:
        raise RuntimeError(f"the ephemeral port range {lo}-{hi} (net.ipv4.ip_local_port_range) leaves no "
                           f"room for {span} port(s) below or above it; narrow it")
    rng = random.Random()
    for _ in range(500):
        port = rng.randrange(first, last)
        socks = []
        try:
            for p in range(port, port + span):
                s = socket.socket()
                socks.append(s)
                s.bind((host, p))
            return port
        except OSError:
            continue
        finally:
            for s in socks:
                s.close()
    raise RuntimeError(f"no {span} free TCP port(s) in a row in {first}-{last + span - 1} on {host} after "
                       "500 tries")
