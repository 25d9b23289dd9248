"""Per-subscription quality of service (:class:`QoS`), as DDS's history and durability policies.

``LATEST`` keeps only the newest message (depth 1: stale ones are dropped and counted), ``KEEP_ALL`` queues
everything (bounded by ``depth``, default :data:`KEEP_ALL_DEPTH`, drops counted), ``LATCHED`` is ``LATEST``
plus the publisher's last value delivered on joining (:class:`flexsheet.runtime.subscription.Subscription`).
"""

from __future__ import annotations

import enum

__all__ = ["QoS", "KEEP_ALL_DEPTH"]

#: default queue bound of a ``KEEP_ALL`` subscription,
#: messages: more than twice the deepest backlog measured (433
#: messages: the 2x load bench's every-topic subscriber on 2 cores, docs/reliability.md), 3.5 s of the fastest
#: topic at twice its rate (joint states, 280 Hz), ~70 s of a
#: 14-node graph's /diagnostics. It was 1 000 000 (no bound in
#: practice: the world's /diagnostics queue could grow without end). A KEEP_ALL subscriber of images passes a
#: smaller ``depth`` (1000 stereo frames are 655 MB)
KEEP_ALL_DEPTH = 1000


class QoS(enum.Enum):
    """Per-subscription quality of service (see module docstring)."""

    LATEST = "latest"
    KEEP_ALL = "keep_all"
    LATCHED = "latched"

