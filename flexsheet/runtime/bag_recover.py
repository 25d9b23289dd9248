"""``bag recover``: a cut or damaged MCAP rewritten as a complete one that any MCAP reader opens.

The source is read with :class:`~flexsheet.runtime.bag_read.McapScan` (chunk CRCs checked, damaged chunks
skipped, a truncated tail dropped); every message that survives is written again, with its schemas, channels,
metadata and attachments, by the ``mcap`` package's own writer, which adds the summary and the footer that a
bag cut by ``kill -9`` lacks. A ``recovered`` metadata record says what was kept and lost.
"""

from __future__ import annotations

import json
from collections import Counter
from pathlib import Path

from mcap.writer import CompressionType, Writer

from flexsheet.runtime.bag_json import FIELD, JSON_ENCODING, PART_OF, Parts
from flexsheet.runtime.bag_read import BagSummary, McapScan

__all__ = ["recover_bag"]


def recover_bag(src: str | Path, dst: str | Path, summary: BagSummary | None = None) -> Counter:
    """Write what is readable of ``src`` to ``dst`` as a complete MCAP. Returns whole messages kept per topic;
    damage and truncation go to ``summary``. Raises ``ValueError`` if ``src`` is not MCAP at all and
    ``FileNotFoundError`` if it is missing. ``src`` and ``dst`` must differ."""
    if Path(src).resolve() == Path(dst).resolve():
        raise ValueError(f"{dst}: recover writes a new file; give an output path other than the input")
    s = summary if summary is not None else BagSummary()
    scan = McapScan(src, s)
    kept: Counter = Counter()
    unknown: Counter = Counter()
    parts = Parts()
    with open(dst, "wb") as fh:
        w = Writer(fh, compression=CompressionType.LZ4)
        started = False
        schemas: dict[int, int] = {}
        channels: dict[int, int] = {}

        def start() -> None:
            hdr = scan.header
            w.start(profile=hdr.profile if hdr else "", library="flexsheet bag recover")

        for kind, rec in scan.records():
            if not started:
                start()
                started = True
            if kind == "message":
                cid = rec[0]
                out = channels.get(cid)
                if out is None:
                    ch = scan.channels.get(cid)
                    if ch is None:  # its Channel record was in a damaged part and nothing else names it
                        unknown[f"<channel {cid}>"] += 1
                        continue
                    sid = 0
                    sc = scan.schemas.get(ch.schema_id) if ch.schema_id else None
                    if sc is not None:
                        sid = schemas.get(sc.id) or w.register_schema(sc.name, sc.encoding, sc.data)
                        schemas[sc.id] = sid
                    out = channels[cid] = w.register_channel(ch.topic, ch.message_encoding, sid, ch.metadata)
                w.add_message(out, log_time=rec[2], data=rec[4], publish_time=rec[3], sequence=rec[1])
                ch = scan.channels[cid]
                # an image of a message (flexsheet.runtime.bag_json): counted with it
                if PART_OF in ch.metadata:
                    parts.add(ch.metadata[PART_OF], ch.metadata.get(FIELD, ""), rec[2])
                elif ch.message_encoding != JSON_ENCODING or ch.schema_id not in scan.schemas \
                        or parts.whole(ch.topic, scan.schemas[ch.schema_id].name, rec[2]) is not None:
                    kept[ch.topic] += 1
            elif kind == "metadata" and rec.name != "flexsheet.channel":  # channel ids are renumbered here
                w.add_metadata(rec.name, rec.metadata)
            elif kind == "attachment":
                w.add_attachment(rec.create_time, rec.log_time, rec.name, rec.media_type, rec.data)
        if not started:
            start()
        lost = Counter()
        for d in s.damaged:
            lost.update(d.counts)
        lost.update(unknown)
        w.add_metadata("recovered", {"source": Path(src).name, "kept": json.dumps(dict(kept)),
                                     "lost": json.dumps(dict(lost)), "damaged": str(len(s.damaged)),
                                     "truncated": str(s.truncated).lower(), "cut_bytes": str(s.cut_bytes)})
        w.finish()
    return kept
