"""The preview (flexsheet.viz.preview): it draws a bag's Foxglove channels."""

from __future__ import annotations

import pytest
from mcap.writer import Writer

from flexsheet.runtime.codec import encode
from flexsheet.viz.foxglove_bag import FoxgloveBagChannels
from flexsheet.viz.preview import read_foxglove, render
from flexsheet.viz.samples import sample_state


def test_preview_draws_the_bag(tmp_path):
    path = tmp_path / "fox.mcap"
    with open(path, "wb") as fh:
        w = Writer(fh)
        w.start()
        fox = FoxgloveBagChannels(w)
        for k in range(12):
            t = 1.7e9 + k * 0.1
            for name, msg in sample_state(stamp=t, push=0.0005 * k, seq=k).items():
                fox.add_frames(encode(name, msg), int(t * 1e9))
        fox.close()
        w.finish()
    data = read_foxglove(path)
    numbers = render(data, tmp_path / "p.png")
    assert (tmp_path / "p.png").stat().st_size > 20_000
    drawn = numbers["scene_entities"]
    st = sample_state()
    assert drawn["object:triangles"] == len(st["/object/deformation"].faces)
    assert drawn["arm_left:cylinders"] == 7 and drawn["cameras:lines"] == 16 and drawn[
        "fingertip:spheres"] == 3
    tension = numbers["plots"]["Plot!tension"]["tension (N/m)"]
    assert len(tension) >= 10 and {v for _, v in tension} == {120.0}
    with pytest.raises(ValueError, match="MCAP"):
        read_foxglove(__file__)
