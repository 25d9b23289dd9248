"""``--set`` items of ``flexsheet launch`` and the tools that read a launch file: a node's param
(``NODE.KEY=VALUE``) or a graph-wide override (``hosts.NAME.address=ADDR``, a launch extension's ``KEY=VALUE``
or ``KEY.SUB=VALUE``), handed to every :func:`~flexsheet.runtime.launch.load_launch` of the run through
:data:`~flexsheet.runtime.launch.TOPLEVEL_ENV`."""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

import yaml

from flexsheet.runtime.extensions import sections as launch_sections
from flexsheet.runtime.launch import TOPLEVEL_ENV, LaunchError, load_launch

__all__ = ["parse_toplevel_set", "split_sets", "apply_toplevel_sets"]


def parse_toplevel_set(item: str, node_names) -> tuple[str, Any] | None:
    """A ``--set`` item that overrides a top-level section of a launch extension: ``KEY=VALUE`` or, for a
    mapping section, ``KEY.SUB=VALUE`` (when no node is named KEY). Returns ``(key, value)`` (a mapping
    section's value as ``{SUB: VALUE}``, YAML-parsed), or ``None`` for a node override. Raises
    :class:`LaunchError` on a bad item."""
    known = launch_sections()
    head, dot, rest = item.partition(".")
    if head == "hosts" and "hosts" not in node_names:
        host, dot2, kv = rest.partition(".")
        key, eq, value = kv.partition("=")
        if not dot or not dot2 or not host or not key or not eq:
            raise LaunchError(f"--set {item!r}: expected hosts.NAME.address=ADDRESS")
        return "hosts", {host: {key: yaml.safe_load(value)}}
    if dot and head in known and known[head].parse_set is None and head not in node_names:
        key, eq, value = rest.partition("=")
        if not eq or not key:
            raise LaunchError(f"--set {item!r}: expected {head}.KEY=VALUE")
        return head, {key: yaml.safe_load(value)}
    key, eq, value = item.partition("=")
    if key == "base_port" and eq and "base_port" not in node_names:
        port = yaml.safe_load(value)
        if not isinstance(port, int) or not 1024 <= port <= 65000:
            raise LaunchError(f"--set {item!r}: base_port must be an integer in 1024..65000 (the graph's "
                              "first TCP port; two graphs on one machine need ports apart)")
        return "base_port", port
    if eq and "." not in key:
        if key not in known or known[key].parse_set is None:
            forms = [f"{k}=VALUE" if s.parse_set else f"{k}.KEY=VALUE" for k, s in known.items()]
            forms += ["hosts.NAME.address=ADDRESS", "base_port=PORT"]
            raise LaunchError(f"--set {item!r}: a top-level override is one of {', '.join(forms)}; a node "
                              "param is NODE.KEY=VALUE")
        return key, known[key].parse_set(value)
    return None


def split_sets(items: list[str], node_names, toplevel: dict | None = None) -> tuple[dict, dict[str, dict]]:
    """``--set`` items split into the top-level overrides (merged into ``toplevel``: ``hosts`` host by host, a
    mapping section key by key) and the node params (node → {param: YAML value}). Raises :class:`LaunchError`
    for an item that is neither."""
    toplevel = dict(toplevel or {})
    nodes: dict[str, dict] = {}
    for item in items:
        top = parse_toplevel_set(item, node_names)
        if top is None:
            node, dot, kv = item.partition(".")
            key, eq, value = kv.partition("=")
            if not dot or not eq or not key:
                raise LaunchError(f"--set {item!r}: expected NODE.KEY=VALUE, or a top-level section's "
                                  "KEY=VALUE or KEY.SUB=VALUE (e.g. scene=FILE, twin.truth_seed=3, "
                                  "hosts.main.address=127.0.0.1)")
            nodes.setdefault(node, {})[key] = yaml.safe_load(value) if value else ""
            continue
        key, value = top
        if key == "hosts":
            merged = dict(toplevel.get("hosts", {}))
            for host, spec in value.items():
                merged[host] = {**merged.get(host, {}), **spec}
            toplevel["hosts"] = merged
        else:
            toplevel[key] = {**toplevel.get(key, {}), **value} if isinstance(value, dict) else value
    return toplevel, nodes


def apply_toplevel_sets(items: list[str], path: str | Path) -> dict:
    """Apply the top-level ``--set`` items of a tool that reads launch file ``path``
    (``hosts.NAME.address=…``, ``twin.truth_seed=…``, ``scene=…``) for this process (:data:`TOPLEVEL_ENV`), so
    that every later :func:`load_launch` sees them as the launcher's processes do; returns them. Raises
    :class:`LaunchError` for a node override (``NODE.KEY=VALUE``: only ``flexsheet launch`` takes those) or a
    bad item."""
    toplevel, nodes = split_sets(items, set(load_launch(path).nodes),
                                 json.loads(os.environ.get(TOPLEVEL_ENV) or "{}"))
    if nodes:
        raise LaunchError(f"--set {next(iter(nodes))}.…: a node param; here only a graph-wide setting "
                          "(hosts.NAME.address=ADDRESS, twin.truth_seed=N, scene=FILE)")
    if toplevel:
        os.environ[TOPLEVEL_ENV] = json.dumps(toplevel)
    return toplevel
