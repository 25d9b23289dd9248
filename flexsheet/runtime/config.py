"""How a node is configured: :class:`NodeConfig` (its wiring and raw params), and what an unusable
configuration is (:class:`ConfigError`, exit status :data:`EXIT_CONFIG`)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from flexsheet.runtime.zmq.curve import CurveConfig

__all__ = ["NodeConfig", "ConfigError", "EXIT_CONFIG"]

#: exit status of a node whose configuration is unusable (BSD ``sysexits.h`` EX_CONFIG):
#: a bad param, a missing or unreadable file a param names, a ``ValueError`` from
#: :meth:`flexsheet.runtime.node.Node.setup`. The supervisor never respawns it.
EXIT_CONFIG = 78


class ConfigError(ValueError):
    """The node's configuration cannot work (message names the param and value). Raised from
    :meth:`flexsheet.runtime.node.Node.setup` (a ``ValueError`` or ``FileNotFoundError`` there is turned into
    one); ``flexsheet run`` exits with :data:`EXIT_CONFIG` and the launcher does not respawn the node."""


@dataclass
class NodeConfig:
    """How a node is wired: its name, type, host, bound endpoint, peer endpoints and raw params.

    Filled by the launcher (:mod:`flexsheet.runtime.launch_config`) or ``flexsheet run``. ``params`` are
    validated against the node's ``Params`` model in :meth:`flexsheet.runtime.node.Node.__init__`, before any
    socket opens. ``remaps`` rename topics (``{"/fingertip": "/fingertip_raw"}``).
    """

    name: str
    node_type: str = ""
    host: str = "localhost"
    endpoint: str = "tcp://127.0.0.1:0"
    peers: list[str] = field(default_factory=list)
    params: dict[str, Any] = field(default_factory=dict)
    remaps: dict[str, str] = field(default_factory=dict)
    heartbeat_period: float = 1.0
    curve: CurveConfig | None = None

