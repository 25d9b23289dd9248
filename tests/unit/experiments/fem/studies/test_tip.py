"""The fold study's tip-refined sequence (flexsheet/experiments/fem/studies/tip.py): its convergence
verdict."""

import numpy as np
import pytest


def test_the_tip_sequence_verdict_needs_three_levels_a_falling_difference_and_a_quiet_tip_check():
    from flexsheet.experiments.fem.studies.tip import tip_verdict

    depths = np.array([0.0025, 0.005, 0.0075])
    good = np.array([[0.2, 0.6, 0.9], [0.1, 0.2, 0.3]])          # mm: coarse, middle vs the finest
    v = tip_verdict(good, depths, True, 0, None)
    assert v["converged"] and v["monotone_decrease"] and v["last_refinement_change_mm"] == pytest.approx(0.3)
    assert v["converged_to_depth_mm"] == pytest.approx(7.5)
    assert tip_verdict(good, depths, True, 0, 0.30)["converged"]
    assert not tip_verdict(good, depths, True, 0, 0.80)["converged"]          # a finer tip still moves it
    assert "tip_check" in tip_verdict(good, depths, True, 0, 0.80)["criterion"]
    assert not tip_verdict(good[1:], depths, True, 0, None)["converged"]     # two levels
    assert not tip_verdict(good, depths, False, 0, None)["converged"]        # Newton failed on the finest
    assert not tip_verdict(good, depths, True, 3, None)["converged"]         # inverted elements
    worse = np.array([[0.2, 0.6, 0.9], [0.1, 0.7, 0.3]])        # not falling at 5 mm, and over 0.35 mm there
    w = tip_verdict(worse, depths, True, 0, None)
    assert (not w["converged"] and not w["monotone_decrease"]
            and w["converged_to_depth_mm"] == pytest.approx(2.5))
