"""Bags in MCAP (the ``mcap`` package): record, play, info, export, recover.

* Record (:mod:`~flexsheet.runtime.bag_write`) stores each message's raw wire frames (``meta`` + array
  buffers, msgpack-framed as one record, no re-encoding: lossless) on a channel per topic, with message
  encoding ``flexsheet-msgpack`` and the message's pydantic JSON schema (encoding ``jsonschema``). It trusts
  nothing: a message that is not a flexsheet envelope is stored as it came (``flexsheet-raw``), and what is
  lost (publisher sequence gaps, a full queue, write errors) is counted in the bag's metadata and the
  recorder's heartbeat. Chunks are small (256 KiB, LZ4, written at least once a second) and unbuffered, so a
  bag cut by a crash or ``kill -9`` stays readable up to its last complete chunk; a respawned recorder writes
  the time it was down as ``/recorder/gap`` records.
* Read (:mod:`~flexsheet.runtime.bag_read`) checks every chunk's CRC; a damaged chunk is skipped and reported
  with what it held, the rest of the file is read. ``bag info`` reads any MCAP.
* Play republishes the same frames with the original relative timing (``--rate`` scales it), from a node
  endpoint, so that subscribers cannot tell a replay from a live run.
* Export (:mod:`~flexsheet.runtime.bag_export`) transcodes to JSON-encoded MCAP with jsonschema
  (Foxglove/Lichtblick open it); image fields become ``foxglove.CompressedImage`` (PNG) channels.
* Recover (:mod:`~flexsheet.runtime.bag_recover`) rewrites a cut or damaged bag as a complete MCAP.

Source: MCAP specification (mcap.dev/spec), Foxglove schemas (foxglove.CompressedImage).
"""

from __future__ import annotations

import argparse
import asyncio
import json
import sys
import time
from pathlib import Path
from typing import Literal

from pydantic import BaseModel, ConfigDict, Field

from flexsheet.runtime import lockstep
from flexsheet.runtime.bag_export import export_bag
from flexsheet.runtime.bag_json import JSON_ENCODING
from flexsheet.runtime.bag_read import (
    ENCODING,
    MAGIC,
    BagSummary,
    bag_info,
    clock_text,
    read_bag,
)
from flexsheet.runtime.bag_recover import recover_bag
from flexsheet.runtime.bag_write import BagWriter
from flexsheet.runtime.config import NodeConfig
from flexsheet.runtime.discovery import resolve_graph
from flexsheet.runtime.node import Node
from messages import Heartbeat, TopicStats

__all__ = ["RecorderNode", "PlayerNode", "check_mcap"]


def check_mcap(path: str | Path) -> None:
    """Raise ``FileNotFoundError`` or ``ValueError`` (one line naming ``path``) unless it is an MCAP file."""
    p = Path(path)
    if not p.is_file():
        raise FileNotFoundError(f"{path}: no such file")
    with open(p, "rb") as fh:
        if fh.read(len(MAGIC)) != MAGIC:
            raise ValueError(f"{path}: not an MCAP file (no MCAP magic at its start)")


# ------------------------------------------------------------------------------------------------ nodes
class RecorderParams(BaseModel):
    """``output``: .mcap path (``$(out)`` allowed); ``topics``: topics to record (empty: all); ``foxglove``:
    also write the Foxglove scene channels while recording (costs the recorder a decode per message; off by
    default on a small machine — ``flexsheet bag export`` adds them afterwards)."""

    model_config = ConfigDict(extra="forbid")
    output: str = "bag.mcap"
    topics: list[str] = Field(default_factory=list)
    foxglove: bool = False


class RecorderNode(Node):
    """Records raw frames of the live graph into an MCAP bag (QoS keep-all; nothing is decoded). Its heartbeat
    has one subscription entry per recorded topic (``count`` stored, ``dropped`` lost to sequence gaps,
    ``rejected`` stored raw as malformed) and says ``warn`` with the counts once anything was lost or
    malformed, ``error`` after a write error."""

    Params = RecorderParams
    node_type = "recorder"

    async def setup(self) -> None:
        self.writer = BagWriter(self.params.output, foxglove=self.params.foxglove)
        self._last_counts: dict[str, int] = {}
        for t in self.params.topics or [""]:
            self.transport.subscribe(t)
        self.log.info("recording %s to %s", ", ".join(self.params.topics) or "all topics", self.writer.path)

    def _on_frames(self, frames: list) -> None:  # raw frames straight from the transport
        try:
            if self.params.topics and bytes(frames[0]).decode(errors="replace") not in self.params.topics:
                return
        except (IndexError, TypeError):
            pass   # no topic frame: stored (or counted) by the writer all the same
        # log time: the wall clock, or on a simulated clock when the message left its node (deterministic)
        clock = self.clock
        self.writer.write(frames, round(clock.stamp() * 1e9) if clock.simulated else time.time_ns())

    def heartbeat(self) -> Heartbeat:
        hb = super().heartbeat()
        w = getattr(self, "writer", None)
        if w is None:
            return hb
        period = self.config.heartbeat_period
        subs = list(hb.subscriptions)
        for topic in sorted(set(w.counts) | set(w.malformed)
                            | {t for t in w.dropped if not t.startswith("<")}):
            n = w.counts[topic] + w.malformed[topic]
            rate = (n - self._last_counts.get(topic, 0)) / period
            self._last_counts[topic] = n
            subs.append(TopicStats(topic=topic, type="", qos="keep_all", rate_hz=rate, count=n,
                                   dropped=w.dropped[topic], rejected=w.malformed[topic]))
        malformed, lost = sum(w.malformed.values()), w.lost
        update: dict = {"subscriptions": subs}
        if w.error or not w._thread.is_alive():
            update.update(state="error", message=f"bag write error: {w.error or 'writer thread stopped'}")
        elif malformed or lost:
            parts = ", ".join(f"{k} {v}" for k, v in sorted(w.dropped.items()))
            update.update(state="error" if hb.state == "error" else "warn",
                          message=f"bag {w.path.name}: {sum(w.counts.values())} stored, {malformed} "
                                  f"malformed (stored raw), {lost} lost" + (f" ({parts})" if parts else ""))
        return hb.model_copy(update=update)

    async def teardown(self) -> None:
        self.writer.close()
        self.log.info("bag %s: %d messages on %d topics, %d malformed (stored raw), %d lost%s",
                      self.writer.path,
                      sum(self.writer.counts.values()), len(self.writer.counts),
                      sum(self.writer.malformed.values()),
                      self.writer.lost, f"; write error: {self.writer.error}" if self.writer.error else "")


class PlayerParams(BaseModel):
    """``file``: bag to play; ``rate``: speed factor; ``loop``; ``topics`` (empty: all); ``start_delay`` s
    before the first message (subscribers connect); ``exit_when_done``; ``mode``: ``realtime`` (the bag's
    timing × ``rate``) or ``lockstep`` (as fast as the nodes of the player's container handle it, each message
    handled before the next, on the bag's clock: :mod:`flexsheet.runtime.lockstep`)."""

    model_config = ConfigDict(extra="forbid")
    file: str
    rate: float = Field(default=1.0, gt=0.0)
    loop: bool = False
    topics: list[str] = Field(default_factory=list)
    start_delay: float = Field(default=0.5, ge=0.0)
    exit_when_done: bool = True
    mode: Literal["realtime", "lockstep"] = "realtime"


_PLAY_LEAD_S = 0.005  # s; see PlayerNode._play


class PlayerNode(Node):
    """Republishes a bag's raw frames with the original relative timing, from this node's endpoint."""

    Params = PlayerParams
    node_type = "player"
    #: a bag may hold rendered stereo pairs (two 1024 x 768 RGB images): sizes the send queue
    LARGEST_MESSAGE_BYTES = 2 * 1024 * 768 * 3 + (16 << 10)

    async def setup(self) -> None:
        try:
            check_mcap(self.params.file)
        except FileNotFoundError:
            raise ValueError(f"file: bag {self.params.file!r} not found") from None
        self.done = asyncio.Event()
        self.sent = 0
        if self.params.mode == "lockstep":
            lockstep.check(self)  # ConfigError (exit 78) unless the player is in a lockstep container
            self._task = asyncio.get_running_loop().create_task(lockstep.play(self))
            return
        ep = self.transport.endpoint or ""
        if ep.startswith("tcp://"):   # a player is only a publisher: say how to watch it
            self.log.info("playing %s on %s: watch with 'flexsheet topic hz TOPIC' (it finds this player on "
                          "this machine; elsewhere --endpoint %s), or the live view: 'flexsheet run viz "
                          "--peer %s' (Foxglove at ws://localhost:8765)", self.params.file, ep, ep, ep)
        asyncio.get_running_loop().create_task(self._play_safely())

    async def _play_safely(self) -> None:
        try:
            await self._play()
        except (ValueError, OSError) as exc:  # the file became unreadable: say so in one line and stop
            self.log.error("cannot play %s: %s", self.params.file, exc)
            self.errors_total += 1
            self.done.set()
            if self.params.exit_when_done:
                self.shutdown()

    async def _play(self) -> None:
        await asyncio.sleep(self.params.start_delay)
        latched = {t.name for t in __import__("messages.topics", fromlist=["ALL"]).ALL if t.latched}
        summary = BagSummary()
        while True:
            t0_bag = t0 = None
            for m in read_bag(self.params.file, self.params.topics or None, summary=summary):
                # anchor once the bag is open, a little ahead: the first message then waits
                if t0_bag is None:
                    t0_bag = m.log_time  # through the same timer as the rest and shares their wake-up latency
                    t0 = time.monotonic() + _PLAY_LEAD_S
                due = t0 + (m.log_time - t0_bag) / self.params.rate
                delay = due - time.monotonic()
                if delay > 0:
                    await asyncio.sleep(delay)
                if m.topic in latched:
                    self.transport.set_latched(m.topic, m.frames)
                self.transport.send(m.frames)
                self.sent += 1
            if not self.params.loop or t0_bag is None:
                break
        self.log.info("played %d messages from %s", self.sent, self.params.file)
        if summary.damaged or summary.truncated:
            self.log.warning("%s: %d damaged parts skipped (%d messages lost)%s; see flexsheet bag info",
                             self.params.file, len(summary.damaged), summary.lost,
                             ", cut short" if summary.truncated else "")
        self.done.set()
        if self.params.exit_when_done:
            await asyncio.sleep(0.2)
            self.shutdown()


# ------------------------------------------------------------------------------------------------ CLI
def _graph(launch: str | None, endpoints: list[str] | None = None):
    """(peers, curve) of the graph to record (:func:`flexsheet.runtime.discovery.resolve_graph`)."""
    g = resolve_graph(launch, endpoints)
    return g.peers, g.curve


def _fail(verb: str, exc: Exception) -> int:
    print(f"flexsheet bag {verb}: {exc}", file=sys.stderr)
    return 2


def cmd_record(args: argparse.Namespace) -> int:
    import logging
    logging.basicConfig(level="INFO", format="%(levelname)s %(name)s: %(message)s")
    out = args.output or time.strftime("bag_%Y%m%d_%H%M%S.mcap")
    try:
        peers, curve = _graph(args.launch, getattr(args, "endpoint", None))
    except (LookupError, ValueError) as exc:   # LaunchError is a ValueError
        return _fail("record", exc)
    node = RecorderNode(NodeConfig(name="bag_record", node_type="recorder", endpoint="", peers=peers,
                                   curve=curve,
                                   params={"output": out, "topics": args.topics}))

    async def main() -> None:
        if args.duration:
            asyncio.get_running_loop().call_later(args.duration, node.shutdown)
        await node.run()

    asyncio.run(main())
    w = node.writer
    if getattr(args, "json", False):
        print(json.dumps({"file": str(w.path), "messages": sum(w.counts.values()), "counts": dict(w.counts),
                          "malformed": dict(w.malformed), "lost": w.lost,
                          "error": str(w.error or "") or None}))
        return 1 if w.error else 0
    print(f"wrote {w.path}: {sum(w.counts.values())} messages, {sum(w.malformed.values())} malformed (stored "
          f"raw), {w.lost} lost")
    return 1 if w.error else 0


def cmd_play(args: argparse.Namespace) -> int:
    import logging
    try:
        check_mcap(args.file)
    except (OSError, ValueError) as exc:
        return _fail("play", exc)
    logging.basicConfig(level="INFO", format="%(levelname)s %(name)s: %(message)s")
    node = PlayerNode(NodeConfig(name="bag_play", node_type="player", endpoint=args.endpoint, peers=[],
                                 params={"file": args.file, "rate": args.rate, "loop": args.loop,
                                         "topics": args.topics or [], "start_delay": args.start_delay}))
    asyncio.run(node.run())
    if getattr(args, "json", False):
        print(json.dumps({"file": str(args.file), "sent": node.sent, "errors": node.errors_total}))
    return 1 if node.errors_total else 0


#: log times below this (s, 2001-09-09) are a simulated clock's: ``clock: sim`` graphs start at 1000 s
#: (:data:`flexsheet.runtime.lockstep.SIM_EPOCH`); a wall-clock bag is always later
SIMULATED_BEFORE = 1e9


def _when(t: float) -> str:
    """A log time as the bag's clock means it: a simulated time in seconds, a wall time as a local date."""
    if t < SIMULATED_BEFORE:
        return f"{t:.3f} s simulated"
    return time.strftime("%Y-%m-%d %H:%M:%S", time.localtime(t))


def print_damage(s: BagSummary, out=sys.stdout) -> None:
    """The ``damaged:``, ``cut:`` and ``gaps:`` lines of ``bag info`` / ``bag recover``."""
    if s.damaged:
        print(f"damaged:   {len(s.damaged)} unreadable part(s) skipped, {s.lost} messages lost "
              f"({sum(d.length for d in s.damaged)} bytes)", file=out)
        for d in s.damaged[:20]:
            print(f"  {d.describe()}", file=out)
        if len(s.damaged) > 20:
            print(f"  … and {len(s.damaged) - 20} more", file=out)
    if s.truncated:
        span = (f", a partial chunk of {clock_text(s.cut_span[0])}–{clock_text(s.cut_span[1])}" if s.cut_span
                else "")
        print(f"cut:       TRUNCATED: the file ends before its footer; {s.cut_bytes} bytes at the end "
              f"unreadable{span} (flexsheet bag recover writes a complete copy)", file=out)
    for g in s.gaps:
        if g.get("topic") == "":
            lost = g.get("lost_s")
            print(f"gap:       recorder restarted after {g.get('previous')}: "
                  f"{f'{lost:.2f} s' if lost is not None else 'unknown time'} without recording", file=out)


def _plain(o):
    """JSON-able: mapping keys as strings ("a/b" for a tuple), tuples as lists."""
    if isinstance(o, dict):
        return {"/".join(map(str, k)) if isinstance(k, tuple) else str(k): _plain(v) for k, v in o.items()}
    if isinstance(o, (list, tuple)):
        return [_plain(v) for v in o]
    return o


def _damage_json(s: BagSummary) -> dict:
    """What ``bag info --json`` says of damage, for the other verbs' ``--json``."""
    import dataclasses

    return {"damaged": [_plain(dataclasses.asdict(d)) if dataclasses.is_dataclass(d) else str(d)
                        for d in s.damaged],
            "lost": s.lost, "truncated": s.truncated, "cut_bytes": s.cut_bytes}


def cmd_info(args: argparse.Namespace) -> int:
    try:
        s = bag_info(args.file)
    except (ValueError, OSError) as exc:
        return _fail("info", exc)
    size = Path(args.file).stat().st_size
    if getattr(args, "json", False):
        dur = s.end - s.start if s.end > s.start else 0.0
        print(json.dumps({
            "file": str(args.file), "bytes": size, "start": s.start, "end": s.end, "duration_s": dur,
            "clock": "sim" if s.end and s.start < SIMULATED_BEFORE else "wall",
            "topics": {t: {"count": n, "rate_hz": n / dur if dur else 0.0, "type": s.schemas.get(t, ""),
                           "encoding": s.encodings.get(t, "")} for t, n in sorted(s.counts.items())},
            "dropped": dict(s.dropped), "malformed": dict(s.malformed), **_damage_json(s)}, default=str))
        return 1 if s.damaged or s.truncated else 0
    print(f"file:      {args.file} ({size / 1e6:.2f} MB)")
    print(f"duration:  {s.end - s.start:.3f} s  (start {_when(s.start)}, end {_when(s.end)})" if s.end
          else "duration:  - (no messages)")
    lost_wire = sum(v for k, v in s.dropped.items() if not k.startswith("<"))
    other = {k: v for k, v in s.dropped.items() if k.startswith("<") and v}
    print(f"messages:  {sum(s.counts.values())}   dropped on the wire: {lost_wire}"
          + "".join(f"   {k.strip('<>')}: {v}" for k, v in sorted(other.items()))
          + (f"   malformed (stored raw): {sum(s.malformed.values())}" if s.malformed else ""))
    print_damage(s)
    w = max((len(t) for t in s.counts), default=5)
    for topic, n in sorted(s.counts.items()):
        rate = n / (s.end - s.start) if s.end > s.start else 0.0
        kind = s.schemas.get(topic) or s.encodings.get(topic, "")
        enc = "" if s.encodings.get(topic) in (ENCODING, JSON_ENCODING) else f"  [{s.encodings.get(topic)}]"
        print(f"  {topic:<{w}}  {n:7d} msgs  {rate:8.1f} Hz  {kind}{enc}")
    for topic, n in sorted(s.malformed.items()):
        print(f"  {topic:<{w}}  {n:7d} msgs  malformed, stored raw")
    return 1 if s.damaged or s.truncated else 0


def cmd_export(args: argparse.Namespace) -> int:
    s = BagSummary()
    t0 = time.monotonic()

    def progress(share: float, n: int) -> None:
        print(f"export: {share * 100:5.1f} %  {n} messages  {time.monotonic() - t0:.1f} s", file=sys.stderr,
              flush=True)

    try:
        check_mcap(args.file)
        counts = export_bag(args.file, args.output, foxglove=not args.no_foxglove, summary=s,
                            progress=progress)
    except (ValueError, OSError) as exc:
        return _fail("export", exc)
    if getattr(args, "json", False):
        print(
            json.dumps({"file": str(args.file), "output": str(args.output),
                        "counts": dict(sorted(counts.items())),
                        **_damage_json(s)}))
        return 1 if s.damaged or s.truncated else 0
    print(f"wrote {args.output}: " + ", ".join(f"{k} {v}" for k, v in sorted(counts.items())))
    print_damage(s)
    return 1 if s.damaged or s.truncated else 0


def cmd_recover(args: argparse.Namespace) -> int:
    s = BagSummary()
    try:
        kept = recover_bag(args.file, args.output, summary=s)
    except (ValueError, OSError) as exc:
        return _fail("recover", exc)
    if getattr(args, "json", False):
        print(
            json.dumps({"file": str(args.file), "output": str(args.output),
                        "kept": dict(sorted(kept.items())),
                        **_damage_json(s)}))
        return 0
    print(f"wrote {args.output}: {sum(kept.values())} messages kept on {len(kept)} topics")
    for topic, n in sorted(kept.items()):
        print(f"  kept {topic}: {n}")
    print_damage(s)
    if not s.damaged and not s.truncated:
        print("lost:      nothing (the input was complete and undamaged)")
    return 0
