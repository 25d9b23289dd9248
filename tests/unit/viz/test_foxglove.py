"""The Foxglove channels (flexsheet.viz.foxglove): each output names its inputs."""

from __future__ import annotations

from flexsheet.viz.foxglove import inputs_for


def test_outputs_name_their_inputs():
    assert [t.name for t in inputs_for("/camera/left")] == ["/camera/stereo"]
    scene_in = {t.name for t in inputs_for("/viz/scene")}
    assert {"/object/deformation", "/arm/left/joint_state", "/world/finger"} <= scene_in
    assert "/camera/stereo" not in scene_in
    assert [t.name for t in inputs_for("/fingertip")] == ["/fingertip"] and inputs_for("/nope") == []
