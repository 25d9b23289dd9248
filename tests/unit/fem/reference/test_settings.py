"""The reference runs' settings (flexsheet/fem/reference/settings.py): the full settings judge the node's snapshot
mesh against a finer one."""

import numpy as np
import pytest

pytestmark = [pytest.mark.timeout(1500), pytest.mark.slow]   # the slow tier, with the FEM experiment's quick run


def test_full_settings_judge_the_nodes_snapshot_mesh_against_a_finer_one():
    """The node's snapshot table (DEFAULT_REF_SPEC) is one of the full convergence study's meshes and the
    snapshots the experiment judges are taken on it, against a finer mesh: the accuracy reported is the
    node's, and it includes its mesh's own error. The levels refine by ~1.33 each."""
    from flexsheet.fem.reference.settings import settings_for
    from flexsheet.fem.snapshots import DEFAULT_GRID, DEFAULT_REF_SPEC

    st = settings_for(False)
    lv = st.levels
    assert len(lv) >= 3 and DEFAULT_REF_SPEC in lv and st.snap_spec == DEFAULT_REF_SPEC
    assert lv[-1].h_fine < DEFAULT_REF_SPEC.h_fine
    ratios = [a.h_fine / b.h_fine for a, b in zip(lv[:-1], lv[1:], strict=True)]
    assert all(1.2 < r < 1.45 for r in ratios), ratios
    # every held-out azimuth lies strictly between two snapshot azimuths (interpolated, not a snapshot itself),
    # and the snapshots are no farther apart than the node table's widest interval (10 deg)
    ga = st.grid.angles_deg
    assert st.holdout_deg and all(a not in ga and ga[0] < a < ga[-1] for a in st.holdout_deg)
    # the snapshot azimuths are the node table's, solved at its depth step (its cached paths, not extra solves)
    assert set(ga) <= set(DEFAULT_GRID.angles_deg) and st.fine_step == DEFAULT_GRID.depth_step
    node_widest = max(np.diff(DEFAULT_GRID.angles_deg))
    assert node_widest == 10.0 and max(np.diff(ga)) <= node_widest
