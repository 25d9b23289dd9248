"""The reference runs' settings (flexsheet/fem/reference/settings.py): the full settings judge the node's
snapshot mesh against a finer one."""

import numpy as np
import pytest

# the slow tier, with the FEM experiment's quick run
pytestmark = [pytest.mark.timeout(1500), pytest.mark.slow]


def test_full_settings_judge_their_snapshot_mesh_against_a_finer_one():
    """The full study's snapshot mesh (STUDY_SPEC) is one of its convergence meshes, the next-to-finest, and
    the snapshots it judges are taken on it, against a finer mesh; the node's own table mesh
    (DEFAULT_REF_SPEC) is one of the levels' sizes too, with the support's rim on a mesh line. The levels
    refine by ~1.33 each."""
    from flexsheet.fem.reference.settings import STUDY_SPEC, settings_for
    from flexsheet.fem.snapshots import DEFAULT_GRID, DEFAULT_REF_SPEC

    st = settings_for(False)
    lv = st.levels
    assert len(lv) >= 3 and lv[-2] == STUDY_SPEC and st.snap_spec == STUDY_SPEC
    assert lv[-1].h_fine < STUDY_SPEC.h_fine
    assert DEFAULT_REF_SPEC.h_fine in [x.h_fine for x in lv] and DEFAULT_REF_SPEC.rim and not STUDY_SPEC.rim
    ratios = [a.h_fine / b.h_fine for a, b in zip(lv[:-1], lv[1:], strict=True)]
    assert all(1.2 < r < 1.45 for r in ratios), ratios
    # every held-out azimuth lies strictly between two snapshot azimuths (interpolated, not a snapshot
    # itself), and the snapshots are no farther apart than the node table's widest interval (10 deg)
    ga = st.grid.angles_deg
    assert st.holdout_deg and all(a not in ga and ga[0] < a < ga[-1] for a in st.holdout_deg)
    # the snapshot azimuths are among the node table's, at its depth step
    assert set(ga) <= set(DEFAULT_GRID.angles_deg) and st.fine_step == DEFAULT_GRID.depth_step
    node_widest = max(np.diff(DEFAULT_GRID.angles_deg))
    assert node_widest == 10.0 and max(np.diff(ga)) <= node_widest
