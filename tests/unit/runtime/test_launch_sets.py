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


def test_base_port_moves_a_whole_graph_and_a_bad_one_is_refused(monkeypatch):
    import json

    from flexsheet.dirs import launch_dir
    from flexsheet.runtime.launch import TOPLEVEL_ENV, load_launch

    assert parse_toplevel_set("base_port=9400", {"w"}) == ("base_port", 9400)
    with pytest.raises(LaunchError, match=r"base_port must be an integer in 1024..65000"):
        parse_toplevel_set("base_port=80", {"w"})
    sim = launch_dir() / "sim.yaml"
    before = load_launch(str(sim)).base_port
    monkeypatch.setenv(TOPLEVEL_ENV, json.dumps({"base_port": 9400}))
    assert before != 9400 and load_launch(str(sim)).base_port == 9400
