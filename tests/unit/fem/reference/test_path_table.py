"""A scene's path table command (flexsheet/fem/reference/path_table.py): the assembly turns a station's
reference push into exactly the reference, and the arguments a path table does not take are refused. The model
(fixture ``model``) is tests/unit/conftest.py's."""

from __future__ import annotations

import numpy as np
import pytest

from flexsheet.fem.path_snapshots import check_path_table
from flexsheet.fem.scene_model import finger_on_scene
from flexsheet.model.scenes import SCENES_DIR


def test_assembly_turns_a_station_push_into_its_reference(model):
    """assemble_path_table on reference pushes that differ from the linear model's by a known field and force:
    the table served at that station and depth is the reference (the correction and ratios are exact)."""
    from flexsheet.fem.reference import path_table as P

    m = model
    m.path_table = None
    depths = np.asarray(P._st()["depths"])
    fr = np.array([0.0, 1.0])
    pts, nrm = m.scene.stroke_at(fr)
    refs = []
    for i, (q, n) in enumerate(zip(pts, nrm, strict=True)):
        u_lin, f_lin, _ = P._linear(m, m.scene, q, n, depths)
        extra = (2e-4 * (i + 1)) * np.ones_like(u_lin) * (depths[:, None, None] / depths[-1])
        refs.append({"u": u_lin + extra, "force": f_lin * 1.3 + 0.2 * depths,
                     "inverted": np.zeros(len(depths)),
                     "max_strain": np.full(len(depths), 0.1), "converged": np.ones(len(depths), bool)})
    t = P.assemble_path_table(m.scene, m, fr, refs)
    check_path_table(t)
    assert t["depths"][-1] == pytest.approx(depths[-1]) and len(t["depths"]) == len(depths) + 1
    # a station whose Newton solve failed at the 6th depth: the table stops at the 5th, for every station
    stalled = [dict(r) for r in refs]
    stalled[0]["converged"] = np.arange(len(depths)) < 5
    short = P.assemble_path_table(m.scene, m, fr, stalled)
    assert short["depths"][-1] == pytest.approx(depths[4]) and short["correction"].shape[1] == 6
    stalled[1]["converged"] = np.zeros(len(depths), bool)
    with pytest.raises(ValueError, match="did not converge at the first depth"):
        P.assemble_path_table(m.scene, m, fr, stalled)
    m.attach_path_table(t)
    try:
        j = 1
        fg = finger_on_scene(pts[1], nrm[1], float(depths[j]), m.finger_radius)
        up = m.update_finger(fg)
        assert up.method == "path_snapshots"
        want = refs[1]["u"][j].copy()
        want[m.mesh.fixed[m.surface_nodes]] = 0.0
        # inside: put on the finger
        out = np.linalg.norm(m.rest_vertices + want - fg.center, axis=1) >= fg.radius
        assert out.sum() > 0.9 * len(out)
        assert np.abs((up.vertices.astype(float) - m.rest_vertices) - want)[out].max() < 1e-6
        assert up.force == pytest.approx(refs[1]["force"][j], rel=1e-6)
    finally:
        m.path_table = None


def test_the_cli_refuses_what_a_path_table_does_not_take(tmp_path):
    from flexsheet.experiments.fem.cli import main

    box = str(SCENES_DIR / "rounded_box.yaml")
    out = str(tmp_path / "out")
    with pytest.raises(SystemExit, match="--stations and --holdout-fraction"):
        main(["--scene", box, "--node-table", "--azimuth", "10", "--out", out])
    with pytest.raises(SystemExit, match="--stations must be >= 2, got 1"):
        main(["--scene", box, "--node-table", "--stations", "1", "--out", out])
    with pytest.raises(SystemExit, match=r"--holdout-fraction 0.5 must lie in \(0, 1\) between the stations"):
        main(["--scene", box, "--node-table", "--holdout-fraction", "0.5", "--out", out])
    with pytest.raises(SystemExit, match=r"--holdout-fraction 1.2 must lie"):
        main(["--scene", box, "--node-table", "--stations", "4", "--holdout-fraction", "1.2", "--out", out])
