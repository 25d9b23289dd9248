"""Docs that are generated or executed stay true: docs/messages.md, CLI --help examples."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from flexsheet.runtime import docgen

ROOT = Path(__file__).resolve().parents[3]


def test_messages_md_is_up_to_date():
    assert (ROOT / "docs" / "messages.md").read_text() == docgen.render(), \
        "docs/messages.md is stale: run python -m flexsheet.runtime.docgen"


@pytest.mark.parametrize("cmd", [[], ["launch"], ["run"], ["topic"], ["node"], ["bag"], ["calibrate"],
                                 ["experiment"], ["bench"]])
def test_every_subcommand_help_shows_an_example(cmd):
    out = subprocess.run([sys.executable, "-m", "flexsheet", *cmd, "--help"], capture_output=True, text=True,
                         timeout=60, cwd=ROOT)
    assert out.returncode == 0, out.stderr
    assert "example:" in out.stdout and "flexsheet " in out.stdout.split("example:")[1]
