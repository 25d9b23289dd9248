"""Launch extensions: top-level launch-file sections and ``--check`` rules that a layer above the runtime
adds, the way ``launch_ros`` adds ROS to ``launch`` without the core knowing it.

An extension is a :class:`LaunchExtension` named in the ``flexsheet.launch_extensions`` entry-point group of
an installed package (pyproject.toml). The runtime loads them on first use; it imports none of them by name.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import dataclass, field
from importlib.metadata import entry_points
from typing import Any

__all__ = ["LaunchSection", "LaunchExtension", "extensions", "sections", "bag_channels", "ENTRY_POINT_GROUP",
           "BAG_CHANNELS_GROUP"]

ENTRY_POINT_GROUP = "flexsheet.launch_extensions"
#: extra bag channels written beside the lossless ones
#: (``foxglove``: the 3-D scene, flexsheet.viz.foxglove_bag)
BAG_CHANNELS_GROUP = "flexsheet.bag_channels"


@dataclass(frozen=True)
class LaunchSection:
    """One top-level key of a launch file.

    ``key``: the YAML key; ``type``: what its value validates as (a pydantic-validatable type, ``None``
    allowed); ``node_value(value, lf, out)``: the value handed to every node whose ``Params`` has a field
    named ``key`` and leaves it unset (``None``: nothing is handed); ``parse_set(text)``: the value of
    ``--set KEY=TEXT`` (``None`` here: the section takes ``--set KEY.SUB=VALUE`` items merged into a mapping
    instead); ``description``: one line for ``--help`` and errors."""

    key: str
    type: Any
    node_value: Callable[[Any, Any, str | None], Any]
    parse_set: Callable[[str], Any] | None = None
    description: str = ""


@dataclass(frozen=True)
class LaunchExtension:
    """What one layer adds to launch files.

    ``sections``: its top-level keys; ``before_launch(lf, check_only)``: run by ``flexsheet launch`` after the
    file validates and before any node starts; returns top-level values to set (e.g. a registration's output
    file; what it says goes to the logging module) — raises ``flexsheet.runtime.launch.LaunchError``;
    ``check(checker)``: extra ``--check`` rules (``checker.err``/``warn``/``params``); ``file_readers``: param
    name → reader that raises ``ValueError``/``OSError`` for an input file it cannot use; ``input_params``:
    further param names whose value is an input file that must exist (no reader); ``output_params``: (node
    type, param) → ``"file"``/``"dir"`` written by the node; ``listen_params``: node type → (host param, port
    param); ``node_topics``: node type → params → its
    :class:`~flexsheet.runtime.graph_builder.NodeTopics` (what it publishes, what it cannot work without);
    ``shared_values``: the :class:`~flexsheet.runtime.graph_builder.SharedValue` pairs its node types must
    agree on (both read by :class:`~flexsheet.runtime.graph_builder.GraphBuilder`)."""

    name: str
    sections: tuple[LaunchSection, ...] = ()
    before_launch: Callable[..., dict] | None = None
    check: Callable[[Any], None] | None = None
    file_readers: dict[str, Callable[[str], None]] = field(default_factory=dict)
    input_params: frozenset[str] = frozenset()
    output_params: dict[tuple[str, str], str] = field(default_factory=dict)
    listen_params: dict[str, tuple[str, str]] = field(default_factory=dict)
    node_topics: dict[str, Callable[[Any], Any]] = field(default_factory=dict)
    shared_values: tuple[Any, ...] = ()


@functools.cache
def extensions() -> tuple[LaunchExtension, ...]:
    """Every installed launch extension, in entry-point name order. Raises ``TypeError`` naming an entry point
    that is not a :class:`LaunchExtension`."""
    found = []
    for ep in sorted(entry_points(group=ENTRY_POINT_GROUP), key=lambda e: e.name):
        ext = ep.load()
        if not isinstance(ext, LaunchExtension):
            raise TypeError(f"entry point {ep.name} = {ep.value} ({ENTRY_POINT_GROUP}) is not a "
                            "LaunchExtension")
        found.append(ext)
    return tuple(found)


@functools.cache
def sections() -> dict[str, LaunchSection]:
    """Key → :class:`LaunchSection` over every extension (one dict, shared: do not mutate)."""
    return {s.key: s for ext in extensions() for s in ext.sections}


@functools.cache
def bag_channels(name: str):
    """The class that writes the extra bag channels ``name`` (entry point of :data:`BAG_CHANNELS_GROUP`; built
    with the MCAP writer, then ``add_frames(frames, t_ns)`` per message and ``close()``). Raises
    ``LookupError`` when no installed package provides ``name``."""
    for ep in entry_points(group=BAG_CHANNELS_GROUP, name=name):
        return ep.load()
    raise LookupError(f"no bag channels named {name!r} ({BAG_CHANNELS_GROUP} entry points); is flexsheet "
                      "installed (pip install -e .)?")
