"""What the finger feels against what the object asks (flexsheet.experiments.report_softness): the true sheet's
force over the object's, from a bag."""

import numpy as np
import pytest

from flexsheet.experiments.report_softness import felt_force
from messages import ContactTruth, Header, ObjectDeformation


def _sheet(t: float, depth: float, force: float) -> ContactTruth:
    return ContactTruth(header=Header(stamp=t), touching=True, depth=depth, force=force, point=np.zeros(3),
                        stiffness=force / depth)


def _deformation(t: float, force: float) -> ObjectDeformation:
    return ObjectDeformation(header=Header(stamp=t + 0.004), vertices=np.zeros((3, 3), np.float32),
                             faces=np.array([[0, 1, 2]], dtype=np.int32), contact_force=force, stiffness=100.0,
                             depth=0.01, contact_point=np.zeros(3), method="linear", source_stamp=t)


def _bag(felt_per_mm: float, object_per_mm: float, n: int = 100) -> dict:
    """A press to 10 mm: the sheet at 50 Hz, the object's force at 48 Hz from fingertips exposed 5 ms earlier."""
    sheet, defs = [], []
    for k in range(n):
        t = 1.0 + k * 0.02
        depth = 0.001 + 0.009 * k / (n - 1)                     # 1 -> 10 mm: the first ones below 2 mm
        sheet.append((t, _sheet(t, depth, felt_per_mm * depth * 1e3)))
    for k in range(int(n * 0.02 * 48)):
        t = 1.0 - 0.005 + k / 48.0
        depth = 0.001 + 0.009 * min(max((t + 0.005 - 1.0) / (0.02 * (n - 1)), 0.0), 1.0)
        defs.append((t, _deformation(t, object_per_mm * depth * 1e3)))
    return {"/world/contact": sheet, "/object/deformation": defs}


def test_a_sheet_as_stiff_as_the_object_is_within_the_weber_fraction_and_a_softer_one_is_not():
    same = felt_force(_bag(0.10, 0.10))
    assert same["n"] > 70 and same["verdict"] == "met"
    assert same["ratio"]["median"] == pytest.approx(1.0, abs=0.05)   # the 48 Hz object lags the sheet a little
    assert same["within_weber"] > 0.9
    assert same["felt_stiffness_n_per_m"] == pytest.approx(100.0, rel=1e-6)
    soft = felt_force(_bag(0.07, 0.10))                          # 30 % softer than asked: noticeable
    assert soft["verdict"] == "MISSED" and soft["ratio"]["median"] == pytest.approx(0.7, abs=0.04)
    assert soft["within_weber"] < 0.1
    # a stiffness_scale of 0.7 (the planner's, from the run's start) asks for that softer sheet
    assert felt_force(_bag(0.07, 0.10), scales=[(0.0, 0.7)])["verdict"] == "met"
    # a scale set mid-press applies from then on only: half the samples judged at 0.7, half at 1
    half = felt_force(_bag(0.07, 0.10), scales=[(0.0, 1.0), (2.0, 0.7)])
    assert 0.4 < half["within_weber"] < 0.6


def test_no_press_no_object_force_or_a_bad_scale():
    bag = _bag(0.1, 0.1)
    assert felt_force({"/world/contact": bag["/world/contact"]}) == {}
    assert felt_force({**bag, "/world/contact": [(t, _sheet(t, 0.001, 0.1)) for t, _ in bag["/world/contact"]]}) == {}
    with pytest.raises(ValueError, match="scale"):
        felt_force(bag, scales=[(0.0, 0.0)])
