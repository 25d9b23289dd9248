"""Domains: several graphs on one machine, as ROS 2's ``ROS_DOMAIN_ID``.

A graph runs in domain ``D`` (``FLEXSHEET_DOMAIN_ID``, or ``--domain D`` on ``flexsheet launch`` and every
tool, which sets that variable for the processes it starts; default 0). In domain ``D`` every TCP port a
launch file gives on this machine moves up by ``DOMAIN_STRIDE * D`` (:func:`shift_port`): ``base_port``, a
node's ``port`` and each node param named ``port`` or ``*_port`` whose node's ``host`` param is absent or a
loopback address (a real controller's address and port stay as written). Port 0 (the OS picks) stays 0. Local
discovery (:mod:`flexsheet.runtime.discovery`) shows each tool the nodes of its own domain only. DDS maps its
domains to port ranges the same way (7400 + 250 D).

:func:`port_holder` names the process that holds a TCP port, for the one line a launch prints when a port it
needs is taken.
"""

from __future__ import annotations

import os
import re

import psutil

__all__ = ["DOMAIN_ENV", "DOMAIN_STRIDE", "MAX_DOMAIN", "domain_id", "shift_port", "shift_params",
           "port_holder"]

DOMAIN_ENV = "FLEXSHEET_DOMAIN_ID"
#: ports between two domains: room for 250 nodes and listening params per launch file
DOMAIN_STRIDE = 250
#: the largest domain: the shipped files' highest port (15 042) moves to at most 30 042, below Linux's default
#: ephemeral range (32 768), so a restarted node's port cannot be taken by a client's source port
MAX_DOMAIN = 60
_LOOPBACK = ("127.", "localhost", "::1")


def domain_id(value: int | str | None = None) -> int:
    """The domain: ``value`` if given, else ``$FLEXSHEET_DOMAIN_ID``, else 0. Raises ``ValueError`` naming the
    source and the value unless it is an int in 0..:data:`MAX_DOMAIN`."""
    source = "--domain" if value is not None else DOMAIN_ENV
    raw = value if value is not None else os.environ.get(DOMAIN_ENV, "").strip()
    if raw == "":
        return 0
    if type(raw) is int:
        d = raw
    elif isinstance(raw, str) and re.fullmatch(r"[0-9]+", raw.strip()):
        d = int(raw)
    else:
        d = -1
    if not 0 <= d <= MAX_DOMAIN:
        raise ValueError(f"{source} must be an integer in 0..{MAX_DOMAIN}, got {raw!r}")
    return d


def shift_port(port: int, domain: int) -> int:
    """``port`` in ``domain`` (m: a TCP port): ``port + DOMAIN_STRIDE * domain``; 0 stays 0."""
    return port + DOMAIN_STRIDE * domain if port else port


def shift_params(params: dict, domain: int) -> dict:
    """A node's ``params`` with its local ports moved to ``domain`` (see the module doc); the input is
    unchanged."""
    if not domain:
        return params
    host = params.get("host")
    if isinstance(host, str) and not host.startswith(_LOOPBACK):
        return params
    return {k: shift_port(v, domain) if (k == "port" or k.endswith("_port")) and type(v) is int else v
            for k, v in params.items()}


def port_holder(port: int) -> str:
    """Who listens on TCP ``port`` on this machine: "pid N (command line)", or "" when no process is seen."""
    try:
        conns = psutil.net_connections(kind="tcp")
    except (psutil.Error, OSError):
        return ""
    for c in conns:
        if c.laddr and c.laddr.port == port and c.status == psutil.CONN_LISTEN and c.pid:
            try:
                cmd = " ".join(psutil.Process(c.pid).cmdline())[:160]
            except psutil.Error:
                cmd = "?"
            return f"pid {c.pid} ({cmd})"
    return ""
