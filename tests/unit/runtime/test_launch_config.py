"""Node configuration from a launch file (flexsheet.runtime.launch_config): a launch extension's section
reaches the nodes whose params take it."""

from __future__ import annotations

from pathlib import Path

from flexsheet.display.launch import TwinSpec
from flexsheet.runtime.launch import load_launch
from flexsheet.runtime.launch_config import node_config


def _write(tmp_path: Path, text: str) -> Path:
    p = tmp_path / "l.yaml"
    p.write_text("name: t\n" + text + "nodes:\n  w: {type: world}\n  tk: {type: talker}\n")
    return p


def test_a_section_reaches_the_nodes_whose_params_take_it(tmp_path):
    lf = load_launch(_write(tmp_path, "twin: {truth_seed: 4, realism: ideal, registration: false}\n"
                                      "display_calib: $(launch_dir)/d.yaml\n"))
    assert lf.section("twin") == TwinSpec(truth_seed=4, realism="ideal", registration=False)
    world = node_config(lf, "w").params
    assert world["twin"] == {"realism": "ideal", "truth_seed": 4}
    assert "display_calib" not in world                     # the world's Params has no such field
    assert node_config(lf, "tk").params == {}                # nor the talker's: nothing handed to it
    assert lf.section("scene") is None
