"""What installed packages plug in: node types and commands declared as entry points (``pyproject.toml``),
read with :mod:`importlib.metadata`. The runtime names none of them itself.

- ``flexsheet.nodes`` (:data:`NODES_GROUP`): node type → its :class:`~flexsheet.runtime.node.Node` subclass,
  as ``"module:Class"`` (``flexsheet run TYPE``, a launch file's ``type:``);
- any other group of ``"module:attribute"`` entries (``flexsheet.benches``, a port's sources) is read with
  :func:`table`, one entry loaded with :func:`plugin`.

An entry is imported only when it is used (:func:`node_class`), so ``flexsheet --help`` stays fast and a
broken module breaks only its own node type.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from importlib.metadata import entry_points
from typing import Annotated

from pydantic import AfterValidator

__all__ = ["NODES_GROUP", "table", "node_types", "node_class", "unknown_node_type", "plugin", "EntryName",
           "EntryGroup"]

#: the entry-point group of the node types
NODES_GROUP = "flexsheet.nodes"


@functools.cache
def table(group: str) -> dict[str, str]:
    """Name → ``"module:attribute"`` of every entry point of ``group``, sorted by name (empty when no
    installed package declares one: is flexsheet installed, ``pip install -e .``?). Shared: do not mutate."""
    return {ep.name: ep.value for ep in sorted(entry_points(group=group), key=lambda e: e.name)}


def node_types() -> dict[str, str]:
    """Node type → ``"module:Class"`` of every installed node type (:data:`NODES_GROUP`), sorted by type."""
    return table(NODES_GROUP)


def unknown_node_type(name: str) -> str:
    """The one-line error for node type ``name`` that no installed package declares, naming the known ones."""
    return f"unknown node type {name!r}; known: {', '.join(sorted(node_types()))}"


def node_class(name: str) -> type:
    """The :class:`~flexsheet.runtime.node.Node` subclass of node type ``name``, its module imported now.
    Raises ``LookupError`` (:func:`unknown_node_type`) for an unknown type, and ``ImportError`` or
    ``AttributeError`` when its module cannot be imported here."""
    for ep in entry_points(group=NODES_GROUP, name=name):
        return ep.load()
    raise LookupError(unknown_node_type(name))


def plugin(group: str, name: str, what: str = "entry", base: type | None = None) -> object:
    """The object installed as ``name`` in entry-point ``group``, its module imported now; with ``base``, a
    subclass of it. Raises ``LookupError`` naming ``what`` and the installed names when there is none, or when
    it is not a ``base``."""
    for ep in entry_points(group=group, name=name):
        obj = ep.load()
        if base is not None and not (isinstance(obj, type) and issubclass(obj, base)):
            raise LookupError(f"{what} {name!r} ({group}) is {obj!r}, not a {base.__name__}")
        return obj
    known = ", ".join(table(group)) or "none (is flexsheet installed: pip install -e .?)"
    raise LookupError(f"unknown {what} {name!r} ({group}); known: {known}")


@dataclass(frozen=True)
class EntryGroup:
    """The marker :func:`EntryName` leaves in its field's metadata: the entry-point ``group`` the field
    names an entry of, and ``what`` one is called (a graph builder finds a node's sources by it)."""

    group: str
    what: str


def EntryName(group: str, what: str) -> object:  # noqa: N802 - a type, used as one in a model's field
    """A pydantic field type: a ``str`` that names an installed entry point of ``group`` (an open set: any
    package may add one; nothing lists the names in code). A name not installed fails validation with
    ``unknown <what> 'NAME'; installed: …``. Example: ``source: EntryName("flexsheet.camera_sources",
    "camera source") = "sim"``. The field's metadata carries an :class:`EntryGroup`."""
    def check(name: str) -> str:
        if name not in table(group):
            known = ", ".join(table(group)) or "none (is flexsheet installed: pip install -e .?)"
            raise ValueError(f"unknown {what} {name!r}; installed: {known}")
        return name
    return Annotated[str, AfterValidator(check), EntryGroup(group, what)]
