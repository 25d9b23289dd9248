"""Launch extensions (flexsheet/runtime/extensions.py): the display's sections reach the runtime only through the
``flexsheet.launch_extensions`` entry point, are validated with errors naming the key and value, are handed to
the nodes that take them, and take ``--set`` overrides."""

from __future__ import annotations

from pathlib import Path

import pytest

from flexsheet.display.launch import TwinSpec
from flexsheet.runtime.extensions import bag_channels, extensions, sections
from flexsheet.runtime.launch import LaunchError, load_launch
from flexsheet.runtime.launch_config import node_config
from flexsheet.runtime.launch_sets import parse_toplevel_set


def _write(tmp_path: Path, text: str) -> Path:
    p = tmp_path / "l.yaml"
    p.write_text("name: t\n" + text + "nodes:\n  w: {type: world}\n  tk: {type: talker}\n")
    return p


def test_the_display_extension_is_installed_with_its_three_sections():
    assert [e.name for e in extensions()] == ["display"]
    assert sorted(sections()) == ["display_calib", "scene", "twin"]
    assert bag_channels("foxglove").__module__ == "flexsheet.viz.foxglove_bag"
    with pytest.raises(LookupError, match="no bag channels named 'nope'"):
        bag_channels("nope")


def test_sections_are_validated_with_the_key_and_value_named(tmp_path):
    with pytest.raises(LaunchError) as exc:
        load_launch(_write(tmp_path, "twin: {truth_seed: -1, realism: bogus}\nscene: 3\nbogus_section: 1\n"))
    lines = exc.value.lines
    assert any("key 'twin.truth_seed'" in x and "(value -1)" in x for x in lines), lines
    assert any("key 'twin.realism'" in x and "'bogus'" in x for x in lines), lines
    assert any("key 'scene'" in x and "(value 3)" in x for x in lines), lines
    assert any("key 'bogus_section'" in x and "Extra inputs are not permitted" in x for x in lines), lines


def test_a_section_reaches_the_nodes_whose_params_take_it(tmp_path):
    lf = load_launch(_write(tmp_path, "twin: {truth_seed: 4, realism: ideal, registration: false}\n"
                                      "display_calib: $(launch_dir)/d.yaml\n"))
    assert lf.section("twin") == TwinSpec(truth_seed=4, realism="ideal", registration=False)
    world = node_config(lf, "w").params
    assert world["twin"] == {"realism": "ideal", "truth_seed": 4}
    assert "display_calib" not in world                     # the world's Params has no such field
    assert node_config(lf, "tk").params == {}                # nor the talker's: nothing handed to it
    assert lf.section("scene") is None


def test_set_overrides_a_section(tmp_path):
    assert parse_toplevel_set("twin.truth_seed=3", {"w"}) == ("twin", {"truth_seed": 3})
    assert parse_toplevel_set("scene=x.yaml", {"w"}) == ("scene", str(Path("x.yaml").resolve()))
    assert parse_toplevel_set("w.rate=3", {"w"}) is None
    with pytest.raises(LaunchError, match="a top-level override is one of .*twin.KEY=VALUE"):
        parse_toplevel_set("bogus=1", {"w"})
