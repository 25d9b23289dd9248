"""The arm PCs' clock offsets the twin draws (flexsheet.twin.lab_clock): within the bound docs/deploy.md
gives, spread over it, fixed per truth seed and arm, none for an ideal truth, and bad arguments named."""

import numpy as np
import pytest

from flexsheet.twin.lab_clock import ARM_CLOCK_OFFSET_MAX, arm_clock_offset


def test_offsets_lie_within_the_documented_bound_and_spread_over_it():
    left = np.array([arm_clock_offset(s, "realistic", "left") for s in range(400)])
    right = np.array([arm_clock_offset(s, "realistic", "right") for s in range(400)])
    assert ARM_CLOCK_OFFSET_MAX == 0.25e-3
    assert np.all(np.abs(left) <= ARM_CLOCK_OFFSET_MAX) and np.all(np.abs(right) <= ARM_CLOCK_OFFSET_MAX)
    assert np.max(np.abs(left - right)) <= 0.5e-3                      # the two arm PCs within 0.5 ms
    # uniform on ±0.25 ms: standard deviation 0.25 ms / √3 = 0.144 ms; both signs; the arms drawn apart
    assert left.std() == pytest.approx(0.25e-3 / np.sqrt(3), rel=0.15)
    assert (left > 0).mean() == pytest.approx(0.5, abs=0.1)
    assert abs(np.corrcoef(left, right)[0, 1]) < 0.15


def test_an_offset_is_fixed_by_seed_and_arm_and_ideal_has_none():
    assert arm_clock_offset(7, "realistic", "left") == arm_clock_offset(7, "realistic", "left")
    assert arm_clock_offset(7, "realistic", "left") != arm_clock_offset(8, "realistic", "left")
    assert arm_clock_offset(7, "ideal", "left") == 0.0 == arm_clock_offset(7, "ideal", "right")


@pytest.mark.parametrize("args, match", [
    ((0, "realistic", "middle"), "arm must be 'left' or 'right', got 'middle'"),
    ((0, "rough", "left"), "realism must be 'realistic' or 'ideal', got 'rough'"),
    ((-1, "realistic", "left"), "truth_seed must be an integer >= 0, got -1"),
])
def test_bad_arguments_are_named(args, match):
    with pytest.raises(ValueError, match=match):
        arm_clock_offset(*args)
