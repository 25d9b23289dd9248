"""Generate ``docs/messages.md`` from the message models (``python -m flexsheet.runtime.docgen``).

The table of each message lists every field but the common ``header`` with its type and description (units and
frames are in the descriptions and the class docstring). A test checks that the committed file is up to date.
"""

from __future__ import annotations

import inspect
import sys
from pathlib import Path

from messages import topics as T
from messages.diagnostics import TopicStats


def _type_name(field) -> str:
    ann = field.annotation
    meta = " ".join(str(m.json_schema.get("description", "")) for m in field.metadata
                    if hasattr(m, "json_schema"))
    if "ndarray" in meta:
        return meta[meta.index("[ndarray") + 1:].rstrip("]").replace("ndarray ", "ndarray ")
    return getattr(ann, "__name__", str(ann)).replace("typing.", "")


def _paragraphs(doc: str) -> str:
    """A docstring as Markdown, each paragraph on one line, paragraphs on consecutive lines (one Markdown
    paragraph: the page stays within the docs' 300 lines) and a bullet list keeping its items."""
    out: list[str] = []
    for block in inspect.cleandoc(doc).split("\n\n"):
        items: list[str] = []
        for line in block.splitlines():
            if line.lstrip().startswith(("- ", "* ")) or not items:
                items.append(line.strip())
            else:
                items[-1] += " " + line.strip()
        out.append("\n".join(items))
    return "\n".join(out)


def render() -> str:
    """The Markdown text of docs/messages.md."""
    lines = ["# Messages (the wire contract)", "",
             "Generated from `messages/` by `python -m flexsheet.runtime.docgen`; do not edit by hand.", "",
             "Every message is a frozen, strict pydantic v2 model with a `header` (`stamp` s on the sender's "
             "clock, `frame_id`, `seq`) and carries its schema name and version on the wire. Arrays travel "
             "as raw buffers (see `flexsheet/runtime/codec.py`). Units are SI; frame `display` is defined in "
             "`flexsheet/model/geometry.py`. Float fields and float arrays must be finite.", "",
             "| topic | type | latched | nominal rate |", "|---|---|---|---|"]
    for t in T.ALL:
        lines.append(f"| `{t.name}` | {t.type.SCHEMA} v{t.type.VERSION} | {'yes' if t.latched else ''} | "
                     f"{t.nominal_hz:g} Hz |")
    seen = set()
    for cls in [t.type for t in T.ALL] + [TopicStats]:
        if cls in seen:
            continue
        seen.add(cls)
        schema = getattr(cls, "SCHEMA", cls.__name__)
        lines += ["", f"## {cls.__name__} (`{schema}`)", _paragraphs(cls.__doc__ or ""), "",
                  "| field | type | description |", "|---|---|---|"]
        for name, f in cls.model_fields.items():
            if name == "header":     # every message's, described above
                continue
            desc = (f.description or "").replace("|", "\\|")
            if not desc:
                for m in f.metadata:
                    if hasattr(m, "json_schema"):
                        desc = m.json_schema.get("description", "").split(" [ndarray")[0]
            lines.append(f"| `{name}` | {_type_name(f)} | {desc} |")
    return "\n".join(lines) + "\n"


def main() -> int:
    out = Path(__file__).resolve().parents[2] / "docs" / "messages.md"
    out.write_text(render())
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
