"""Generated docs stay true (flexsheet.runtime.docgen): docs/messages.md is the rendered message contract."""

from __future__ import annotations

from pathlib import Path

from flexsheet.runtime import docgen

ROOT = Path(__file__).resolve().parents[3]


def test_messages_md_is_up_to_date():
    assert (ROOT / "docs" / "messages.md").read_text() == docgen.render(), \
        "docs/messages.md is stale: run python -m flexsheet.runtime.docgen"
