"""Introspection of the live graph: ``topic list|info|echo|hz|bw`` and ``node list|info`` (``--json`` on every
verb: one JSON document on stdout; ``echo``: one JSON object per message, a line each). The tools that call a
node's services (``param``, ``service``, ``topic pub``) are :mod:`flexsheet.runtime.service_tools`.

Everything comes from what is on the wire now — heartbeats on ``/diagnostics`` and the topic itself —
never from a cache. The endpoints to listen to come from ``--launch FILE``, else ``--endpoint tcp://HOST:PORT``
(repeatable: e.g. a bag player's), else ``$FLEXSHEET_LAUNCH``, else the nodes running on this machine
(:mod:`flexsheet.runtime.discovery`).
"""

from __future__ import annotations

import argparse
import asyncio
import json
import sys
import time

import numpy as np

from flexsheet.runtime.bag import SIMULATED_BEFORE
from flexsheet.runtime.codec import DecodeError, decode, decode_any, peek_stamp
from flexsheet.runtime.discovery import Graph, resolve_graph
from flexsheet.runtime.launch import LaunchError, load_launch
from flexsheet.runtime.zmq.transport import ZmqTransport
from messages import Heartbeat
from messages import topics as T

__all__ = ["graph", "collect_heartbeats", "topic_list", "topic_info", "topic_echo", "topic_hz", "topic_bw",
           "node_list",
           "node_info", "containers_of", "graph_topics", "message_json"]


def graph(args: argparse.Namespace) -> Graph | None:
    """The graph of ``args.launch`` / ``args.endpoint`` (:func:`~flexsheet.runtime.discovery.resolve_graph`),
    or None after saying on stderr, in one line, why there is none."""
    try:
        return resolve_graph(getattr(args, "launch", None), getattr(args, "endpoint", None))
    except (LaunchError, LookupError) as exc:
        print(f"flexsheet: {exc}", file=sys.stderr)
        return None


async def collect_heartbeats(peers: list[str], timeout: float, curve=None,
                             expect: set[str] | None = None) -> dict[str, Heartbeat]:
    """Listen to ``/diagnostics`` on ``peers`` for at most ``timeout`` s, or until every node of ``expect``
    (the launch file's) has been heard; returns node name → latest heartbeat."""
    beats: dict[str, Heartbeat] = {}
    done = asyncio.Event()

    def on_frames(frames: list) -> None:
        try:
            hb = decode(frames, T.DIAGNOSTICS)
        except DecodeError:
            return
        beats[hb.node] = hb
        if expect and expect <= beats.keys():
            done.set()

    tr = ZmqTransport("", peers, curve=curve)
    await tr.start(on_frames)
    tr.subscribe(T.DIAGNOSTICS.name)
    try:
        await asyncio.wait_for(done.wait(), timeout=timeout)
    except TimeoutError:
        pass
    finally:
        tr.close()
    return beats


def _beats(args: argparse.Namespace) -> dict[str, Heartbeat] | None:
    g = graph(args)
    if g is None:
        return None
    beats = asyncio.run(collect_heartbeats(g.peers, args.timeout, g.curve, g.names))
    if not beats:
        print(f"no live nodes heard in {args.timeout:.1f} s ({g.source})")
    return beats


def graph_topics(beats: dict[str, Heartbeat]) -> dict[str, dict]:
    """Topic → ``{"type", "rate_hz", "publishers": [...], "subscribers": [...]}`` from heartbeats; each
    publisher ``{"node", "host", "endpoint", "rate_hz", "count", "dropped"}``, each subscriber
    ``{"node", "host", "qos", "rate_hz", "count", "dropped", "rejected"}`` (rates Hz over the nodes' last
    heartbeat period)."""
    out: dict[str, dict] = {}
    for hb in beats.values():
        for st in hb.publishers:
            t = out.setdefault(st.topic,
                               {"type": st.type, "rate_hz": 0.0, "publishers": [], "subscribers": []})
            t["publishers"].append({"node": hb.node, "host": hb.host, "endpoint": hb.endpoint,
                                    "rate_hz": st.rate_hz,
                                    "count": st.count, "dropped": st.dropped})
            t["rate_hz"] += st.rate_hz
        for st in hb.subscriptions:
            t = out.setdefault(st.topic,
                               {"type": st.type, "rate_hz": 0.0, "publishers": [], "subscribers": []})
            t["subscribers"].append({"node": hb.node, "host": hb.host, "qos": st.qos, "rate_hz": st.rate_hz,
                                     "count": st.count, "dropped": st.dropped, "rejected": st.rejected})
    return dict(sorted(out.items()))


def topic_list(args: argparse.Namespace) -> int:
    """Print every topic published in the live graph with its type, publishers, rate and subscribers."""
    beats = _beats(args)
    if not beats:
        return 2 if beats is None else 1
    topics = graph_topics(beats)
    if getattr(args, "json", False):
        print(json.dumps(topics, indent=1))
        return 0
    w = max(len(t) for t in topics)
    for topic, t in topics.items():
        print(f"{topic:<{w}}  {t['type']:<30} {t['rate_hz']:8.1f} Hz  "
              f"pub: {','.join(p['node'] for p in t['publishers']) or '-'}  "
              f"sub: {','.join(p['node'] for p in t['subscribers']) or '-'}")
    return 0


def topic_info(args: argparse.Namespace) -> int:
    """Print one topic's type, rate, publishers and subscribers (with QoS and drop counts); 1 when no live
    node publishes or subscribes it."""
    beats = _beats(args)
    if not beats:
        return 2 if beats is None else 1
    t = graph_topics(beats).get(args.topic)
    if t is None:
        print(f"{args.topic}: no live node publishes or subscribes it (flexsheet topic list shows those that "
              "do)",
              file=sys.stderr)
        return 1
    if args.json:
        print(json.dumps({"topic": args.topic, **t}, indent=1))
        return 0
    print(f"topic: {args.topic}\ntype: {t['type']}\nrate: {t['rate_hz']:.1f} Hz\npublishers: "
          f"{len(t['publishers'])}")
    for p in t["publishers"]:
        print(f"  {p['node']} [{p['host']}] {p['endpoint']}  {p['rate_hz']:.1f} Hz, {p['count']} sent, "
              f"{p['dropped']} dropped")
    print(f"subscribers: {len(t['subscribers'])}")
    for p in t["subscribers"]:
        print(f"  {p['node']} [{p['host']}] qos {p['qos']}  {p['rate_hz']:.1f} Hz, {p['count']} received, "
              f"{p['dropped']} dropped, {p['rejected']} rejected")
    return 0


def containers_of(launch: str | None) -> dict[str, str]:
    """Node name → its ``container:`` in launch file ``launch`` (nodes alone in their process are absent; no
    launch file: none known)."""
    if not launch:
        return {}
    try:
        lf = load_launch(launch)
    except LaunchError:
        return {}
    return {n: s.container for n, s in lf.nodes.items() if s.container}


def _node_entry(hb: Heartbeat, container: str | None) -> dict:
    return {"node": hb.node, "type": hb.node_type, "host": hb.host, "container": container, "pid": hb.pid,
            "endpoint": hb.endpoint, "state": hb.state, "message": hb.message, "uptime_s": hb.uptime,
            "heartbeat_age_s": time.time() - hb.header.stamp, "rejected_total": hb.rejected_total,
            "last_rejection": hb.last_rejection,
            "publishers": [{"topic": st.topic, "type": st.type, "rate_hz": st.rate_hz, "count": st.count,
                            "dropped": st.dropped} for st in hb.publishers],
            "subscriptions": [{"topic": st.topic, "type": st.type, "qos": st.qos, "rate_hz": st.rate_hz,
                               "count": st.count, "dropped": st.dropped, "rejected": st.rejected}
                              for st in hb.subscriptions]}


def node_list(args: argparse.Namespace) -> int:
    """Print every live node with host, container (``-``: its own process), pid, endpoint, state and
    rejection counts. The nodes of one container share its pid."""
    beats = _beats(args)
    if not beats:
        return 2 if beats is None else 1
    containers = containers_of(args.launch)
    if getattr(args, "json", False):
        print(json.dumps([_node_entry(beats[n], containers.get(n)) for n in sorted(beats)], indent=1))
        return 0
    for name in sorted(beats):
        hb = beats[name]
        age = time.time() - hb.header.stamp
        print(f"{name:<18} {hb.node_type:<18} host={hb.host:<8} container={containers.get(name, '-'):<10} "
              f"pid={hb.pid:<7} {hb.endpoint:<24} "
              f"state={hb.state:<5} up={hb.uptime:7.1f}s rejected={hb.rejected_total} "
              f"(heartbeat {age * 1e3:.0f} ms ago){'  ' + hb.last_rejection if hb.last_rejection else ''}")
    return 0


def node_info(args: argparse.Namespace) -> int:
    """Print one live node: host, container, pid, state, its publishers and subscriptions with rates, QoS and
    drop/rejection counts; 1 when no such node is heard."""
    beats = _beats(args)
    if not beats:
        return 2 if beats is None else 1
    hb = beats.get(args.name)
    if hb is None:
        print(f"node {args.name!r} not heard in {args.timeout:g} s; live nodes: {', '.join(sorted(beats))}",
              file=sys.stderr)
        return 1
    e = _node_entry(hb, containers_of(args.launch).get(args.name))
    if args.json:
        print(json.dumps(e, indent=1))
        return 0
    print(f"node: {e['node']} ({e['type']}) host {e['host']} container {e['container'] or '-'} pid "
          f"{e['pid']}\nendpoint: {e['endpoint'] or '-'}\nstate: "
          f"{e['state']}{' (' + e['message'] + ')' if e['message'] else ''}, up {e['uptime_s']:.1f} s, "
          f"{e['rejected_total']} rejected")
    print("publishers:")
    for p in e["publishers"]:
        print(f"  {p['topic']} [{p['type']}] {p['rate_hz']:.1f} Hz, {p['count']} sent, {p['dropped']} "
              "dropped")
    print("subscriptions:")
    for p in e["subscriptions"]:
        print(f"  {p['topic']} [{p['type']}] qos {p['qos']} {p['rate_hz']:.1f} Hz, {p['count']} received, "
              f"{p['dropped']} dropped, {p['rejected']} rejected")
    return 0


def _short(value) -> str:
    if isinstance(value, np.ndarray):
        if value.size <= 16:
            return np.array2string(value, precision=6, suppress_small=True).replace("\n", "")
        return f"<ndarray {value.dtype} {value.shape}>"
    return repr(value)


def _json_value(value, arrays: bool):
    if isinstance(value, np.ndarray):
        return value.tolist() if arrays else {"dtype": str(value.dtype), "shape": list(value.shape)}
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, bytes):
        return {"bytes": len(value)}
    if isinstance(value, (list, tuple)):
        return [_json_value(v, arrays) for v in value]
    if isinstance(value, dict):
        return {str(k): _json_value(v, arrays) for k, v in value.items()}
    if hasattr(value, "__dict__"):
        return {k: _json_value(v, arrays) for k, v in value.__dict__.items()}
    return value if isinstance(value, (str, int, float, bool)) or value is None else repr(value)


def message_json(topic: str, msg, arrays: bool = False) -> dict:
    """A decoded message as a JSON-able dict: ``topic``, ``type`` (schema name), ``version`` and the fields
    (arrays as lists with ``arrays``, else ``{"dtype", "shape"}``; nested messages as dicts)."""
    return {"topic": topic, "type": msg.SCHEMA, "version": msg.VERSION,
            **{k: _json_value(v, arrays) for k, v in msg.__dict__.items()}}


def topic_echo(args: argparse.Namespace) -> int:
    """Print messages of ``args.topic`` as they arrive (arrays shown by shape unless ``--arrays``): exactly
    ``--count`` of them when given; when none arrives within ``--timeout`` s, say so and return 1."""
    g = graph(args)
    if g is None:
        return 2
    peers, curve = g.peers, g.curve
    done = asyncio.Event()
    n = 0

    def on_frames(frames: list) -> None:
        nonlocal n
        if done.is_set() or bytes(frames[0]).decode(errors="replace") != args.topic:
            return          # one drain may hold more than --count messages
        try:
            msg = decode_any(frames)
        except DecodeError as exc:
            print(f"--- rejected: {exc}")
            return
        n += 1
        if getattr(args, "json", False):
            print(json.dumps(message_json(args.topic, msg, args.arrays)), flush=True)
        else:
            print(f"--- {args.topic} [{msg.SCHEMA} v{msg.VERSION}]")
            for k, v in msg.__dict__.items():
                print(f"{k}: {v!r}" if (args.arrays or not isinstance(v, np.ndarray))
                      else f"{k}: {_short(v)}")
        if args.count and n >= args.count:
            done.set()

    async def main() -> int:
        tr = ZmqTransport("", peers, curve=curve)
        await tr.start(on_frames)
        tr.subscribe(args.topic)
        try:
            try:
                await asyncio.wait_for(asyncio.shield(done.wait()), timeout=args.timeout)
            except TimeoutError:
                if n == 0:
                    print(f"no message on {args.topic} in {args.timeout:g} s: nothing in {g.source} "
                          f"publishes it now (flexsheet topic list shows what is published)", file=sys.stderr)
                    return 1
                await done.wait()
        finally:
            tr.close()
        return 0

    try:
        return asyncio.run(main())
    except KeyboardInterrupt:
        return 0


def _listen(args: argparse.Namespace, keep) -> list | None:
    """Subscribe to ``args.topic`` for ``args.window`` s; ``keep(frames)`` per message of it; the list of what
    it returned, or None (the launch file is unusable: said)."""
    g = graph(args)
    if g is None:
        return None
    peers, curve = g.peers, g.curve
    got: list = []

    def on_frames(frames: list) -> None:
        if bytes(frames[0]).decode(errors="replace") == args.topic:
            got.append(keep(frames))

    async def main() -> None:
        tr = ZmqTransport("", peers, curve=curve)
        await tr.start(on_frames)
        tr.subscribe(args.topic)
        try:
            await asyncio.sleep(args.window)
        finally:
            tr.close()

    asyncio.run(main())
    return got


def _time_base(got: list[tuple[float, float | None, int]], window: float) -> tuple[str, np.ndarray, float]:
    """``(clock, periods, span_s)`` of what arrived, as (arrival s, header stamp s, bytes): on a simulated
    graph (every stamp before :data:`~flexsheet.runtime.bag.SIMULATED_BEFORE`) the periods between the
    messages' own stamps, in arrival order (a step back, a looping bag's restart, is left out), so the rate is
    per simulated second however fast the graph runs; else the periods between arrivals on the wall clock over
    the window."""
    stamps = [s for _, s, _ in got]
    if got and all(s is not None and s < SIMULATED_BEFORE for s in stamps):
        d = np.diff(np.array(stamps, dtype=float))
        d = d[d >= 0.0]
        return "sim", d, float(d.sum())
    return "wall", np.diff(np.array([a for a, _, _ in got], dtype=float)), float(window)


def _frame_info(frames: list) -> tuple[float, float | None, int]:
    return time.monotonic(), peek_stamp(frames), sum(len(f) for f in frames)


def topic_hz(args: argparse.Namespace) -> int:
    """Measure the rate of ``args.topic`` over ``--window`` s: mean rate, min/max/std of periods, in simulated
    time on a simulated graph (from the stamps) and wall time otherwise (arrivals), said in the output and as
    ``clock`` in ``--json``; 1 when fewer than two messages arrived."""
    got = _listen(args, _frame_info)
    if got is None:
        return 2
    clock, d, _ = _time_base(got, args.window)
    out = {"topic": args.topic, "window_s": args.window, "messages": len(got), "clock": clock}
    if len(d) >= 1:
        out.update(rate_hz=float(1 / d.mean()) if d.mean() > 0 else 0.0, period_min_s=float(d.min()),
                   period_max_s=float(d.max()), period_std_s=float(d.std()))
    if args.json:
        print(json.dumps(out))
    elif len(d) < 1:
        print(f"{args.topic}: {len(got)} messages in {args.window:.1f} s of wall time")
    else:
        print(f"{args.topic}: average rate {out['rate_hz']:.2f} Hz ({_clock_words(clock)}) over {len(got)} "
              f"msgs  min {out['period_min_s'] * 1e3:.2f} ms max {out['period_max_s'] * 1e3:.2f} ms "
              f"std {out['period_std_s'] * 1e3:.2f} ms")
    return 0 if len(d) >= 1 else 1


def _clock_words(clock: str) -> str:
    return "simulated time, from the stamps" if clock == "sim" else "wall time"


def topic_bw(args: argparse.Namespace) -> int:
    """Measure the bandwidth of ``args.topic`` over ``--window`` s: bytes/s on the wire (every frame of each
    message, topic frame included; per simulated second on a simulated graph, from the stamps) and the mean,
    smallest and largest message; 1 when none arrived."""
    got = _listen(args, _frame_info)
    if got is None:
        return 2
    sizes = [n for _, _, n in got]
    clock, d, span = _time_base(got, args.window)
    if clock == "sim" and len(d):
        span *= len(got) / len(d)   # n messages cover n periods; the span holds len(d) of them
    out = {"topic": args.topic, "window_s": args.window, "messages": len(sizes), "clock": clock,
           "bytes_per_s": float(sum(sizes) / span) if span > 0 else 0.0}
    if sizes:
        out.update(mean_bytes=float(np.mean(sizes)), min_bytes=int(min(sizes)), max_bytes=int(max(sizes)))
    if args.json:
        print(json.dumps(out))
    elif not sizes:
        print(f"{args.topic}: no messages in {args.window:.1f} s of wall time")
    else:
        print(f"{args.topic}: {_si(out['bytes_per_s'])}B/s ({_clock_words(clock)}) from {len(sizes)} msgs  "
              f"mean {_si(out['mean_bytes'])}B min {_si(out['min_bytes'])}B max {_si(out['max_bytes'])}B")
    return 0 if sizes else 1


def _si(x: float) -> str:
    for unit in ("", "k", "M", "G"):
        if abs(x) < 1000 or unit == "G":
            return f"{x:.2f} {unit}" if unit else f"{x:.0f} "
        x /= 1000.0
    return f"{x:.2f} G"         # pragma: no cover - the loop returns
