"""One graph builder: every way of starting a graph (a launch file, a bench, a test) adds its nodes and its
clock to a :class:`GraphBuilder`, and :meth:`GraphBuilder.build` refuses, before anything starts, a graph that
cannot run — as Drake's ``DiagramBuilder::Build()`` refuses a diagram with an unconnected input.

``build()`` raises :class:`GraphRefused` with one line per problem, each naming the node, the field and the
fix:

- **type, params**: a node type that is not installed or cannot be imported here; params its ``Params``
  model refuses;
- **clock**: a source that does not run on the node's clock. A param declared with
  :func:`~flexsheet.runtime.plugins.EntryName` names an entry point (its field carries an
  :class:`~flexsheet.runtime.plugins.EntryGroup`); an entry whose class sets ``simulated_clock`` (True: it
  needs a simulated clock; False: the wall clock) must match the clock, and its ``other_clock`` says what to
  do instead (e.g. the arm bridge's ``source: sim``, the in-process controller twin, on ``clock: wall``). A
  node runs on the graph's clock, or on a simulated one in a container with a lockstep player;
- **input**: an input a node cannot work without (its :class:`NodeTopics` ``required``) that no node of the
  graph publishes and that is not fed from outside (:meth:`GraphBuilder.external`, a launch file's
  ``external:``). A node type declares its topics in :data:`RUNTIME_TOPICS` (the runtime's own) or in a launch
  extension's ``node_topics``; a type with no declaration, or one that publishes what its params name
  (``outputs`` None, e.g. a player of every topic of its bag), may publish anything, and then no input is
  refused. Remaps apply;
- **shared**: a value that two node types hold a copy of and must agree on (:class:`SharedValue`, from a
  launch extension's ``shared_values``): every owner node holds one value and every copy equals it.

``flexsheet launch FILE --check`` (:mod:`flexsheet.runtime.launch_check`), and so every launch, builds the
file's graph with :meth:`GraphBuilder.from_launch`; the built :class:`Graph` also makes a container's members
(:meth:`Graph.members`, the benches).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass
from typing import Any

from pydantic import BaseModel, ValidationError

from flexsheet.runtime.bus import Bus, ContainerTransport
from flexsheet.runtime.config import NodeConfig
from flexsheet.runtime.container import Member
from flexsheet.runtime.extensions import extensions
from flexsheet.runtime.launch import LaunchFile, short_repr
from flexsheet.runtime.node import Node
from flexsheet.runtime.plugins import EntryGroup, node_class, plugin

__all__ = ["GraphBuilder", "Graph", "BuiltNode", "GraphRefused", "Problem", "NodeTopics", "SharedValue",
           "RUNTIME_TOPICS", "CLOCKS", "node_topics", "shared_values"]

#: the clocks a graph runs on
CLOCKS = ("sim", "wall")


@dataclass(frozen=True)
class NodeTopics:
    """The topics of one node (names before its remaps): ``outputs`` it publishes (None: any, named by its
    params at run time) and the ``required`` inputs it cannot work without (an optional input is not
    listed)."""

    outputs: frozenset[str] | None = frozenset()
    required: frozenset[str] = frozenset()


@dataclass(frozen=True)
class SharedValue:
    """A value that nodes of two types must agree on: param ``key`` of every ``owner``-type node (the value in
    force) and its copy ``copy_key`` in every ``copy``-type node; ``why`` says what the copy is for."""

    owner: str
    key: str
    copy: str
    copy_key: str
    why: str = ""


@dataclass(frozen=True)
class Problem:
    """One reason a graph cannot run: ``kind`` (``type``, ``params``, ``clock``, ``input``, ``shared``), the
    ``node`` it names and its one ``line``."""

    kind: str
    node: str
    line: str


class GraphRefused(ValueError):
    """A graph :meth:`GraphBuilder.build` refuses: ``problems`` (:class:`Problem`) and ``lines``, one line
    each naming the node, the field and the fix; the message is every line."""

    def __init__(self, problems: Iterable[Problem]) -> None:
        self.problems = list(problems)
        self.lines = [p.line for p in self.problems]
        super().__init__("\n".join(self.lines))


def _player_topics(p: Mapping[str, Any]) -> NodeTopics:
    topics = p.get("topics") or ()
    return NodeTopics(outputs=frozenset(topics) if topics else None)


#: the runtime's own node types: the recorder subscribes what it records and needs none of it; the player
#: publishes the topics it plays (all of its bag's when it names none); the demo talker publishes /fingertip
RUNTIME_TOPICS: dict[str, Callable[[Mapping[str, Any]], NodeTopics]] = {
    "recorder": lambda p: NodeTopics(),
    "player": _player_topics,
    "talker": lambda p: NodeTopics(outputs=frozenset({"/fingertip"})),
    "listener": lambda p: NodeTopics(),
}


def node_topics() -> dict[str, Callable[[Mapping[str, Any]], NodeTopics]]:
    """Node type → its topics' declaration (params → :class:`NodeTopics`): :data:`RUNTIME_TOPICS` and every
    launch extension's ``node_topics``."""
    table = dict(RUNTIME_TOPICS)
    for ext in extensions():
        table.update(ext.node_topics)
    return table


def shared_values() -> tuple[SharedValue, ...]:
    """Every launch extension's ``shared_values``."""
    return tuple(v for ext in extensions() for v in ext.shared_values)


@dataclass(frozen=True)
class BuiltNode:
    """One node of a built graph: its ``name``, node ``type``, class, validated ``params`` (a dict of the raw
    params as given), ``host`` and ``container``."""

    name: str
    type: str
    cls: type
    params: dict[str, Any]
    host: str
    container: str | None


@dataclass(frozen=True)
class Graph:
    """A graph :meth:`GraphBuilder.build` accepted: its ``name``, ``clock`` and ``nodes`` (name →
    :class:`BuiltNode`, in the order added)."""

    name: str
    clock: str
    nodes: dict[str, BuiltNode]

    def members(self, made: dict[str, Node] | None = None, heartbeat_period: float = 1.0) -> list[Member]:
        """A container :class:`~flexsheet.runtime.container.Member` per node (the container's bus as
        transport); each node made is also put in ``made`` (name → node), as it is made."""
        out = []
        for n in self.nodes.values():
            cfg = NodeConfig(name=n.name, node_type=n.type, endpoint="", params=dict(n.params),
                             heartbeat_period=heartbeat_period)

            def make(bus: Bus, cls: type = n.cls, cfg: NodeConfig = cfg) -> Node:
                node = cls(cfg, transport=ContainerTransport(bus, ""))
                if made is not None:
                    made[cfg.name] = node
                return node
            out.append(Member(n.name, make))
        return out


@dataclass
class _Entry:
    name: str
    type: str
    params: dict[str, Any]
    host: str
    container: str | None
    remaps: dict[str, str]
    cls: type | None = None
    topics: NodeTopics | None = None
    values: dict[str, Any] | None = None          # the validated params (defaults filled), once resolved
    model: type[BaseModel] | None = None


class GraphBuilder:
    """Nodes and a clock, checked together by :meth:`build` (module doc).

    ``clock``: ``sim`` or ``wall``; ``name``: the graph's, for messages. Raises ``ValueError`` for another
    clock."""

    def __init__(self, clock: str = "wall", name: str = "graph") -> None:
        if clock not in CLOCKS:
            raise ValueError(f"clock = {clock!r}: a graph runs on clock sim or wall")
        self.clock, self.name = clock, name
        self._nodes: dict[str, _Entry] = {}
        self._external: set[str] = set()

    def add(self, name: str, node_type: str | None = None, params: Mapping[str, Any] | None = None, *,
            cls: type | None = None, topics: NodeTopics | None = None, host: str = "localhost",
            container: str | None = None, remaps: Mapping[str, str] | None = None) -> GraphBuilder:
        """Add node ``name`` of installed ``node_type`` (a ``flexsheet.nodes`` entry point) with ``params``,
        or of class ``cls`` (a node class that is no entry point; ``node_type`` then only names it), whose
        ``topics`` default to its type's declaration. ``host``/``container``: where it runs; ``remaps``:
        topic → new name. Returns the builder. Raises ``ValueError`` for a name already added or neither a
        type nor a class."""
        if name in self._nodes:
            raise ValueError(f"node {name}: added twice to graph {self.name}")
        if not node_type and cls is None:
            raise ValueError(f"node {name}: give a node type or a class")
        self._nodes[name] = _Entry(name, node_type or getattr(cls, "node_type", "") or cls.__name__,
                                   dict(params or {}), host, container, dict(remaps or {}), cls, topics)
        return self

    def external(self, *topics: str) -> GraphBuilder:
        """Declare ``topics`` fed from outside the graph (a tool, another launch file): no node of the graph
        need publish them. Returns the builder."""
        self._external.update(topics)
        return self

    @classmethod
    def from_launch(cls, lf: LaunchFile, params_of: Callable[[str], Mapping[str, Any]] | None = None,
                    ) -> GraphBuilder:
        """The builder of launch file ``lf``'s whole graph (every host): its clock, nodes (params from
        ``params_of(name)``, default the file's), hosts, containers, remaps and ``external`` topics."""
        b = cls(clock=lf.clock, name=lf.name)
        for name, spec in lf.nodes.items():
            b.add(name, spec.type, params_of(name) if params_of else spec.params, host=spec.host,
                  container=spec.container, remaps=spec.remaps)
        return b.external(*lf.external)

    # ------------------------------------------------------------------------------------------- build
    def problems(self) -> list[Problem]:
        """Every problem of the graph as it stands (module doc), in the order: type and params, clock,
        inputs, shared values."""
        found: list[Problem] = []
        for e in self._nodes.values():
            found += self._resolve(e)
        for e in self._nodes.values():
            found += self._clock_problems(e)
        found += self._input_problems()
        found += self._shared_problems()
        return found

    def build(self) -> Graph:
        """The :class:`Graph`, or :class:`GraphRefused` (a ``ValueError``) carrying every problem, one line
        each, before anything starts."""
        problems = self.problems()
        if problems:
            raise GraphRefused(problems)
        return Graph(self.name, self.clock, {e.name: BuiltNode(e.name, e.type, e.cls, dict(e.params), e.host,
                                                               e.container) for e in self._nodes.values()})

    # ------------------------------------------------------------------------------------------- checks
    def _resolve(self, e: _Entry) -> list[Problem]:
        """Import ``e``'s class and validate its params (``e.values``); the problems found."""
        if e.cls is None:
            try:
                e.cls = node_class(e.type)
            except (LookupError, ImportError, AttributeError) as exc:
                return [Problem("type", e.name, f"node {e.name}: type = {e.type!r}: "
                                f"{' '.join(str(exc).split())[:200]}; install it or fix the type")]
        e.model = getattr(e.cls, "Params", None)
        if e.model is None:
            e.values = dict(e.params)
            return []
        try:
            validated = e.model.model_validate(e.params)
        except ValidationError as exc:
            out = []
            for err in exc.errors():
                key = ".".join(str(p) for p in err["loc"]) or "params"
                out.append(Problem("params", e.name, f"node {e.name}: params.{key} = "
                                   f"{short_repr(err.get('input'))}: {err['msg'][:300]}"))
            return out
        e.values = {k: getattr(validated, k) for k in type(validated).model_fields}
        return []

    def node_clock(self, name: str) -> str:
        """The clock node ``name`` runs on: the graph's, or ``sim`` in a container with a lockstep player.
        Raises ``KeyError`` for a node not added."""
        e = self._nodes[name]
        if self.clock == "sim" or e.container is None:
            return self.clock
        lockstep = any(o.container == e.container and o.host == e.host and o.type == "player"
                       and o.params.get("mode") == "lockstep" for o in self._nodes.values())
        return "sim" if lockstep else self.clock

    def _clock_problems(self, e: _Entry) -> list[Problem]:
        if e.values is None or e.model is None:
            return []
        clock, out = self.node_clock(e.name), []
        for key, info in e.model.model_fields.items():
            group = next((m for m in info.metadata if isinstance(m, EntryGroup)), None)
            value = e.values.get(key)
            if group is None or not isinstance(value, str):
                continue
            try:
                source = plugin(group.group, value, what=group.what)
            except (LookupError, ImportError, AttributeError):
                continue        # not installed here: the params check says so
            needs = getattr(source, "simulated_clock", None)
            if needs is None or bool(needs) == (clock == "sim"):
                continue
            fix = getattr(source, "other_clock", "") or (f"use a {group.what} for clock {clock}, or run the "
                                                          f"graph on clock {'sim' if needs else 'wall'}")
            out.append(Problem("clock", e.name, f"node {e.name}: params.{key} = {value!r} does not run on "
                               f"clock {clock}: {fix}"))
        return out

    def _topics(self, e: _Entry, table: Mapping[str, Callable]) -> NodeTopics | None:
        """``e``'s topics after its remaps (None: undeclared, or not declarable from its params). A node whose
        type cannot be imported here (another host's) or whose params did not validate is declared from its
        params as given."""
        t = e.topics
        if t is None:
            declare = table.get(e.type)
            if declare is None:
                return None
            try:
                t = declare(e.values if e.values is not None else e.params)
            except (ValueError, TypeError, KeyError):
                return None
        rename = e.remaps.get
        return NodeTopics(None if t.outputs is None else frozenset(rename(x, x) for x in t.outputs),
                          frozenset(rename(x, x) for x in t.required))

    def _input_problems(self) -> list[Problem]:
        table = node_topics()
        declared = {e.name: self._topics(e, table) for e in self._nodes.values()}
        if any(t is None or t.outputs is None for t in declared.values()):
            return []           # a node may publish anything: no input can be shown missing
        published = set(self._external).union(*(t.outputs for t in declared.values()))
        out = []
        for name, t in declared.items():
            for topic in sorted(t.required - published):
                by = _types_publishing(topic, table)
                hint = f"a node of type {' or '.join(by)}" if by else "a node that publishes it"
                out.append(Problem("input", name, f"node {name}: input {topic}: no node of graph {self.name} "
                                   f"publishes it; add {hint}, or declare it external (launch file: "
                                   f"external: [{topic}]) when a tool or another launch file feeds it"))
        return out

    def _shared_problems(self) -> list[Problem]:
        out = []
        for sv in shared_values():
            owners = {e.name: e.values[sv.key] for e in self._nodes.values()
                      if e.type == sv.owner and e.values is not None and sv.key in e.values}
            copies = {e.name: e.values[sv.copy_key] for e in self._nodes.values()
                      if e.type == sv.copy and e.values is not None and sv.copy_key in e.values}
            if not owners or not copies:
                continue
            first, value = next(iter(owners.items()))
            odd = [n for n, v in owners.items() if not _same(v, value)]
            for n in odd:
                out.append(Problem("shared", n, f"node {n}: params.{sv.key} = {short_repr(owners[n])}: node "
                                   f"{first} has {short_repr(value)}, and the {sv.copy} nodes' "
                                   f"{sv.copy_key} copies one value ({sv.why}); give every {sv.owner} node "
                                   f"one {sv.key}"))
            if odd:
                continue
            for n, v in copies.items():
                if not _same(v, value):
                    out.append(Problem("shared", n, f"node {n}: params.{sv.copy_key} = {short_repr(v)}: the "
                                       f"{sv.owner} nodes' {sv.key} is {short_repr(value)} "
                                       f"({', '.join(owners)}; {sv.why}); set {n}.{sv.copy_key}={value!r} or "
                                       f"change their {sv.key}"))
        return out


def _types_publishing(topic: str, table: Mapping[str, Callable]) -> list[str]:
    """The node types whose declaration, at their default params, publishes ``topic`` (for a fix's hint)."""
    found = []
    for node_type, declare in table.items():
        try:
            if topic in (declare({}).outputs or ()):
                found.append(node_type)
        except (ValueError, TypeError, KeyError):
            continue
    return sorted(found)


def _same(a: Any, b: Any) -> bool:
    if isinstance(a, float) and isinstance(b, float):
        return math.isclose(a, b, rel_tol=1e-9, abs_tol=0.0)
    return bool(a == b)
