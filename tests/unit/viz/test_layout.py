"""The shipped Foxglove layout (flexsheet.viz.layout) matches its generator and only names channels (and
fields) that exist."""

from __future__ import annotations

import json
from pathlib import Path

from flexsheet.viz.foxglove import channel_schemas
from flexsheet.viz.layout import layout

ROOT = Path(__file__).resolve().parents[3]


def _leaves(tree) -> list[str]:
    return [tree] if isinstance(tree, str) else _leaves(tree["first"]) + _leaves(tree["second"])


def test_docs_layout_is_the_generated_one_and_names_only_real_channels_and_fields():
    shipped = json.loads((ROOT / "docs" / "foxglove_layout.json").read_text())
    assert shipped == layout(), "regenerate: python -m flexsheet.viz.layout docs/foxglove_layout.json"
    schemas = channel_schemas()
    cfg = shipped["configById"]
    assert sorted(_leaves(shipped["layout"])) == sorted(cfg)          # every panel placed exactly once
    kinds = {k.split("!")[0] for k in cfg}
    assert {"3D", "Image", "Plot"} <= kinds
    for k, c in cfg.items():
        if k.startswith("3D"):
            assert set(c["topics"]) == {"/viz/scene", "/viz/tf"} <= set(schemas)
        if k.startswith("Image"):
            for key in ("imageTopic", "calibrationTopic"):
                if key in c["imageMode"]:
                    assert c["imageMode"][key] in schemas, c["imageMode"][key]
        if k.startswith("Plot"):
            for p in c["paths"]:
                topic, _, field = p["value"].partition(".")
                schema = json.loads(schemas[topic][0].data)
                for part in field.split("."):           # the field exists in the channel's JSON schema
                    assert part in schema["properties"], p["value"]
                    schema = schema["properties"][part]
    titles = " ".join(c.get("title", "") for c in cfg.values())
    assert "Δθ" in titles and "latency" in titles and "tension" in titles
