"""``--set`` items (flexsheet.runtime.launch_sets): a top-level override of a launch extension's section."""

from __future__ import annotations

from pathlib import Path

import pytest

from flexsheet.runtime.launch import LaunchError
from flexsheet.runtime.launch_sets import parse_toplevel_set


def test_set_overrides_a_section(tmp_path):
    assert parse_toplevel_set("twin.truth_seed=3", {"w"}) == ("twin", {"truth_seed": 3})
    assert parse_toplevel_set("scene=x.yaml", {"w"}) == ("scene", str(Path("x.yaml").resolve()))
    assert parse_toplevel_set("w.rate=3", {"w"}) is None
    with pytest.raises(LaunchError, match="a top-level override is one of .*twin.KEY=VALUE"):
        parse_toplevel_set("bogus=1", {"w"})
