"""The served surface in motion (flexsheet/experiments/fem_motion.py): on the organ's path table every frame
of the push (0.25 mm) and of the stroke (0.5 mm) is judged; the drawn dent meets the fingertip within a pixel
and no frame jumps (the stations' solved states blended, not the linear model's contact set, and kept out of
the fingertip sphere); the command writes motion.json and its chart, and a bad scene file is refused with exit
2."""

from __future__ import annotations

import json
import math

import pytest

from flexsheet.experiments.fem_motion import PUSH_STEP, STROKE_STEP, main, motion_run
from flexsheet.model.scenes import SCENES_DIR, load_scene


def test_the_moving_finger_on_the_organ_every_frame_meets_the_fingertip_and_never_jumps(tmp_path):
    sc = load_scene(SCENES_DIR / "organ.yaml")
    out = motion_run(SCENES_DIR / "organ.yaml", str(tmp_path))
    assert "path table" in out["served"]
    c, t = out["contact"], out["temporal"]
    n_push = int(round(sc.use.max_depth / PUSH_STEP))
    n_stroke = int(math.ceil(sc.stroke_length() / STROKE_STEP)) + 1
    assert c["push"]["frames"] == n_push == 60 and c["stroke"]["frames"] == n_stroke
    assert c["push"]["methods"] == ["path_snapshots"] == c["stroke"]["methods"]
    assert len(c["push"]["gap_px"]) == n_push and len(t["push"]["jump_px"]) == n_push - 3
    assert c["gap_px_max"] == max(max(c["push"]["gap_px"]), max(c["stroke"]["gap_px"]))
    # measured: gap 0.51 px, stroke -0.47..-0.38 mm (the rendered triangles'
    # chords under the fingertip: a moved dent left inside it, -0.87 mm, is
    # put on it); jump p99 0.10 px (the linear model's snapping: 2.59 px)
    assert c["gap_px_max"] <= 0.7 and -0.6 < c["stroke"]["gap_mm_range"][0] <= c["stroke"]["gap_mm_range"][
        1] < 0.5
    assert t["jump_px_p99"] <= 0.5 and t["jump_px_p99"] <= t["jump_px_max"] < 1.0
    assert out["verdict"] == {"contact": "met", "temporal": "met"}
    assert 0 < out["realtime"]["update_ms"] < 20 and out["realtime"]["methods"] == ["path_snapshots"]
    assert json.loads((tmp_path / "motion.json").read_text())["temporal"]["jump_px_p99"] == t["jump_px_p99"]
    assert (tmp_path / "motion.png").stat().st_size > 5000


def test_a_bad_scene_file_exits_2_naming_it(tmp_path, capsys):
    bad = tmp_path / "bad.yaml"
    bad.write_text("name: bad\nobject: {kind: sphere, radius: -0.01}\n")
    assert main(["--scene", str(bad), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("fem_motion: ") and "bad.yaml" in err, err
    assert not (tmp_path / "o" / "motion.json").exists()


@pytest.mark.parametrize("argv", [["--help"]])
def test_help_shows_an_example(argv, capsys):
    with pytest.raises(SystemExit) as e:
        main(argv)
    assert (e.value.code == 0
            and "example: python -m flexsheet.experiments.fem_motion --scene" in capsys.readouterr().out)
