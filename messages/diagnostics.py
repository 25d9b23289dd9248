"""Diagnostics: the heartbeat every node publishes on ``/diagnostics`` (1 Hz by default)."""

from __future__ import annotations

from pydantic import BaseModel, ConfigDict, Field

from messages.common import Message

__all__ = ["TopicStats", "Heartbeat"]


class TopicStats(BaseModel):
    """Statistics of one publisher or subscription over the node's lifetime and the last window.

    ``rate_hz``: message rate over the last heartbeat window, Hz. ``count``: messages since start.
    ``dropped``: messages dropped by QoS (latest-only overwrite, queue full, seq gaps on the wire).
    ``rejected``: messages rejected (undecodable, wrong schema/version, invalid field, handler ValueError).
    """

    model_config = ConfigDict(frozen=True, extra="forbid", strict=True)

    topic: str
    type: str = Field(description="schema name")
    qos: str = Field(default="", description="latest | keep_all | latched (subscriptions); '' for publishers")
    rate_hz: float = 0.0
    count: int = 0
    dropped: int = 0
    rejected: int = 0


class Heartbeat(Message):
    """Heartbeat and diagnostics of one node.

    ``node``: node name; ``node_type``: registered type; ``host``: launch-file host name; ``pid``;
    ``endpoint``: the node's bound publisher endpoint (``tcp://addr:port``); ``uptime`` s;
    ``state``: "ok", "warn" or "error"; ``message``: last warning/error line (one line);
    ``publishers``/``subscriptions``: :class:`TopicStats`; ``rejected_total``: all rejections;
    ``last_rejection``: the last rejection reason (one line); ``period``: heartbeat period, s;
    ``service_endpoint``: the node's service socket (:mod:`flexsheet.runtime.services`), "" when it has none.
    """

    SCHEMA = "flexsheet/Heartbeat"
    VERSION = 1

    node: str
    node_type: str = ""
    host: str = "localhost"
    pid: int = 0
    endpoint: str = ""
    uptime: float = 0.0
    state: str = "ok"
    message: str = ""
    publishers: list[TopicStats] = Field(default_factory=list)
    subscriptions: list[TopicStats] = Field(default_factory=list)
    rejected_total: int = 0
    last_rejection: str = ""
    period: float = 1.0
    service_endpoint: str = ""
