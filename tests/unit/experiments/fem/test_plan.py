"""Every reference push a run reads (flexsheet/experiments/fem/plan.py), once by cache key."""

from dataclasses import replace

import numpy as np
import pytest

# the slow tier, with the FEM experiment's quick run
pytestmark = [pytest.mark.timeout(1500), pytest.mark.slow]


def test_planned_solves_list_each_push_the_run_reads_once_by_cache_key():
    """The full run reads 16 distinct reference pushes: five convergence levels, three cut half models, three
    more penalties (the default is level 1's), two skins, azimuth 5 held out and the snapshots' 10 and 20; the
    quick run 5; ``--mirror-study`` the levels and the half models (its stability check reads two levels);
    ``--holdout-study`` the finest level, the snapshot mesh's azimuth-0 level and its cut paths at 5 and 10
    only (the table's blend at 5 reads 0 and 10, not 20)."""
    from flexsheet.experiments.fem.plan import planned_solves
    from flexsheet.experiments.fem.studies.holdout import holdout_grid
    from flexsheet.fem.material import Material
    from flexsheet.fem.reference.paths import push_depths, reference_key
    from flexsheet.fem.reference.settings import settings_for

    probes = np.zeros((1, 3))

    def keys(st, study="full"):
        out = []
        for j in planned_solves(st, study):
            out.append(reference_key(j.spec, j.angle_deg, push_depths(j.step), Material(), probes,
                                     "frictionless", j.penalty_scale))
        return out

    full, quick = settings_for(False), settings_for(True)
    assert len(set(keys(full))) == 16 and len(set(keys(quick))) == 5
    assert len(set(keys(full, "mirror"))) == 8 and set(keys(full, "mirror")) <= set(keys(full))
    hold = planned_solves(full, "holdout")
    assert len(set(keys(full, "holdout"))) == 4 and set(keys(full, "holdout")) <= set(keys(full))
    assert sorted(j.angle_deg for j in hold) == [0.0, 0.0, 5.0, 10.0]
    # the table's pushes and the held-out ones are read as their stable branch (stable_path), the levels not
    assert sorted((j.angle_deg, j.stable, j.spec == full.snap_spec) for j in hold) == \
        [(0.0, False, False), (0.0, True, True), (5.0, True, True), (10.0, True, True)]
    assert {j.spec for j in planned_solves(full) if j.stable} == \
        {full.snap_spec} | {replace(full.levels[-2], skin_h=h) for h in full.skin_sizes}
    assert [j.stable for j in planned_solves(quick)].count(True) == 3
    assert holdout_grid(full).grid.angles_deg == (0.0, 10.0)
    with pytest.raises(ValueError, match="held-out azimuth 25 deg is outside"):
        holdout_grid(replace(full, holdout_deg=(25.0,)))
    assert holdout_grid(replace(full, holdout_deg=(15.0,))).grid.angles_deg == (0.0, 10.0, 20.0)
    with pytest.raises(ValueError, match="hold no azimuth out"):
        holdout_grid(quick)
    # the fold study: the last three levels (the full run's), the tip-refined sequence and its tip check
    assert len(set(keys(full, "fold"))) == 7 and len(set(keys(full, "fold")) & set(keys(full))) == 3
    assert len(set(keys(quick, "fold"))) == 4 and len(set(keys(quick, "fold")) & set(keys(quick))) == 2
    # the material study (per material): the five levels, and the snapshot mesh's stable branch (its table)
    mat = planned_solves(full, "material")
    assert len(set(keys(full, "material"))) == 6 and len(set(keys(full, "material")) & set(keys(full))) == 5
    assert [j.spec for j in mat if j.stable] == [full.snap_spec] == [full.levels[-2]]
    # its tip check is the fold study's (3.4 mm tube + 0.8 mm tip): one solve, shared
    assert set(keys(full, "material")) - set(keys(full)) <= set(keys(full, "fold"))
    assert len(set(keys(quick, "material"))) == 2                       # quick: no tip check
    with pytest.raises(ValueError, match="study must be"):
        planned_solves(full, "mirror_only")
    costs = [j.cost() for j in planned_solves(full)]
    assert costs == sorted(costs, reverse=True)
