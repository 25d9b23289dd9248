"""The run-time tools that call a running node's services (:mod:`flexsheet.runtime.services`):
``param list|get|set``, ``service list|call`` and ``topic pub`` (``--json`` on every verb: one JSON document
on stdout). The node is found from its heartbeat (:mod:`flexsheet.runtime.tools`)."""

from __future__ import annotations

import argparse
import asyncio
import json
import sys
import time

import numpy as np

from flexsheet.runtime.codec import encode
from flexsheet.runtime.discovery import Graph
from flexsheet.runtime.services import ServiceError, call, call_async
from flexsheet.runtime.tools import collect_heartbeats, graph
from messages import topics as T
from messages.common import Header

__all__ = ["param_list", "param_get", "param_set", "service_list", "service_call", "topic_pub"]


def _node_service(args: argparse.Namespace) -> tuple[str, object, bytes | None] | int:
    """(service endpoint, the tool's CURVE config, the node's public key) of ``args.node`` from its heartbeat,
    or an exit code (said on stderr)."""
    g = graph(args)
    if g is None:
        return 2
    curve = g.curve
    beats = asyncio.run(collect_heartbeats(g.peers, args.timeout, curve, {args.node}))
    hb = beats.get(args.node)
    if hb is None:
        print(f"node {args.node!r} not heard in {args.timeout:g} s (heard: "
              f"{', '.join(sorted(beats)) or 'none'}; {g.source})", file=sys.stderr)
        return 1
    if not hb.service_endpoint:
        print(f"node {args.node!r} offers no services (it has no TCP endpoint)", file=sys.stderr)
        return 1
    key = curve.server_keys.get(hb.endpoint) if curve is not None else None
    return hb.service_endpoint, curve, key


def _call(args: argparse.Namespace, service: str, call_args: dict):
    """(True, result) or (False, exit code) after saying why on stderr."""
    found = _node_service(args)
    if isinstance(found, int):
        return False, found
    ep, curve, key = found
    try:
        return True, call(ep, service, call_args, args.timeout, curve, key)
    except ServiceError as exc:
        print(f"{args.node} {service}: {exc}", file=sys.stderr)
        return False, 1


def _yaml_value(text: str):
    import yaml

    try:
        return yaml.safe_load(text)
    except yaml.YAMLError as exc:
        raise SystemExit(f"flexsheet: not a YAML value: {text!r} ({' '.join(str(exc).split())[:200]}"
                         ")") from None


def param_list(args: argparse.Namespace) -> int:
    """Every param of a running node: name, type, value, default, settable at run time, description."""
    ok, rows = _call(args, "param/list", {})
    if not ok:
        return rows
    if args.json:
        print(json.dumps(rows))
        return 0
    for r in rows:
        mark = "  (settable)" if r["dynamic"] else ""
        print(f"{r['name']}: {r['type']} = {r['value']!r} (default {r['default']!r}){mark}")
        if r["description"]:
            print(f"    {r['description']}")
    return 0


def param_get(args: argparse.Namespace) -> int:
    """One param's value."""
    ok, value = _call(args, "param/get", {"name": args.name})
    if not ok:
        return value
    print(json.dumps({"node": args.node, "name": args.name, "value": value}) if args.json else repr(value))
    return 0


def param_set(args: argparse.Namespace) -> int:
    """Set a run-time param (YAML value); prints the value now in effect."""
    ok, value = _call(args, "param/set", {"name": args.name, "value": _yaml_value(args.value)})
    if not ok:
        return value
    print(json.dumps({"node": args.node, "name": args.name, "value": value}) if args.json else
          f"set {args.node}.{args.name} = {value!r}")
    return 0


def service_list(args: argparse.Namespace) -> int:
    """The services of a running node, one line each."""
    ok, rows = _call(args, "list", {})
    if not ok:
        return rows
    print(json.dumps(rows) if args.json else "\n".join(f"{k}: {v}" for k, v in rows.items()))
    return 0


def service_call(args: argparse.Namespace) -> int:
    """Call one service with YAML arguments (a map); prints its result."""
    call_args = _yaml_value(args.args) if args.args else {}
    if not isinstance(call_args, dict):
        print(f"flexsheet: service arguments must be a YAML map, got {args.args!r}", file=sys.stderr)
        return 2
    ok, result = _call(args, args.service, call_args)
    if not ok:
        return result
    print(json.dumps(result) if args.json else repr(result))
    return 0


def _message(topic, data: dict, seq: int, now: float):
    """The topic's message from ``data`` (a YAML map), with a header stamped ``now`` (the graph's clock)
    unless it has one."""
    import re

    data = dict(data)
    data.setdefault("header", {"stamp": float(now), "frame_id": "display", "seq": seq})
    if isinstance(data["header"], dict):
        data["header"] = Header.model_validate(data["header"])
    props = topic.type.model_json_schema().get("properties", {})
    for name, f in topic.type.model_fields.items():
        if f.annotation is np.ndarray and isinstance(data.get(name), list):  # YAML lists → the field's array
            m = re.search(r"dtype=(\w+)", props.get(name, {}).get("description", ""))
            data[name] = np.asarray(data[name], dtype=m.group(1) if m and m.group(1) != "any" else None)
    return topic.type.model_validate(data)


def topic_pub(args: argparse.Namespace) -> int:
    """Publish a message on a topic, ROS 2's ``topic pub``: the message from YAML (its type is the topic's),
    ``--times`` N at ``--rate`` Hz. Every node subscribed to the topic gets each message through its
    ``topic/pub`` service (the tool connects to the graph; the graph never connects to the tool). A topic the
    launch file guards (``security.publishers``) is refused, here and by the nodes."""
    from pydantic import ValidationError

    by_name = {t.name: t for t in T.ALL}
    topic = by_name.get(args.topic)
    if topic is None:
        print(f"flexsheet: unknown topic {args.topic!r}; topics: {', '.join(sorted(by_name))}",
              file=sys.stderr)
        return 2
    data = _yaml_value(args.message) if args.message else {}
    if not isinstance(data, dict):
        print(f"flexsheet: the message must be a YAML map of {topic.type.SCHEMA}'s fields, got "
              f"{args.message!r}",
              file=sys.stderr)
        return 2
    try:
        _message(topic, data, 0, 0.0)                    # refuse a bad message before the graph is asked
    except ValidationError as exc:
        e = exc.errors()[0]
        print(f"flexsheet: {topic.type.SCHEMA} field '{'.'.join(str(x) for x in e['loc'])}': {e['msg']} "
              f"(value {e.get('input')!r})", file=sys.stderr)
        return 2
    g = graph(args)
    if g is None:
        return 2
    guarded = g.launch.security.publishers if g.launch is not None else {}
    if args.topic in guarded:
        print(f"flexsheet: {args.topic} is guarded by the launch file (security.publishers): only "
              f"{', '.join(guarded[args.topic])} may publish it", file=sys.stderr)
        return 1
    return asyncio.run(_publish(args, g, topic, data))


async def _publish(args: argparse.Namespace, g: Graph, topic, data: dict) -> int:
    """``topic pub`` once the message is known good: each subscriber of ``args.topic`` in graph ``g`` gets
    every message by a ``topic/pub`` call to its service socket (:func:`topic_pub`). The tool only connects,
    as a client, so its leaving is a closed connection: the graph never connects to it nor disconnects from
    it."""
    curve = g.curve
    beats = await collect_heartbeats(g.peers, args.timeout, curve, g.names)
    subs = {n: hb for n, hb in beats.items()
            if hb.service_endpoint and any(s.topic == args.topic for s in hb.subscriptions)}
    if not subs:
        print(f"no node of {g.source} subscribes to {args.topic} now", file=sys.stderr)
        return 1
    keys = {n: (curve.server_keys.get(hb.endpoint) if curve is not None else None) for n, hb in subs.items()}
    reached = list(subs)
    for i in range(args.times):         # stamped with the graph's clock (simulated on a simulated graph)
        now = time.time()
        if reached:
            first = subs[reached[0]]
            now = float(await call_async(first.service_endpoint, "clock/now", {}, args.timeout, curve,
                                         keys[reached[0]]))
        frames = [bytes(f) for f in encode(args.topic, _message(topic, data, i, now))]
        for n in list(reached):
            try:
                await call_async(subs[n].service_endpoint, "topic/pub",
                                 {"topic": args.topic, "frames": frames},
                                 args.timeout, curve, keys[n])
            except ServiceError as exc:
                print(f"{n}: {exc}", file=sys.stderr)
                reached.remove(n)
        if i + 1 < args.times:
            await asyncio.sleep(1.0 / args.rate)
    out = {"topic": args.topic, "type": topic.type.SCHEMA, "published": args.times if reached else 0,
           "subscribers": reached}
    print(json.dumps(out) if args.json else
          f"published {out['published']} x {topic.type.SCHEMA} on {args.topic} to "
          f"{', '.join(reached) or 'nobody'}")
    return 0 if reached else 1
