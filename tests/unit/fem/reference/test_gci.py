"""The grid convergence index (flexsheet/fem/reference/gci.py) on sequences whose error is known in closed
form."""

import math

import pytest

from flexsheet.fem.reference.gci import P_MAX, SAFETY, gci, gci_by_depth


@pytest.mark.parametrize("h, p", [((0.008, 0.006, 0.0045), 1.5), ((0.008, 0.0055, 0.0045), 1.2),
                                  ((0.006, 0.0045, 0.0034), 0.8)])
def test_a_power_law_sequence_gives_its_order_and_1_25_times_the_fine_error(h, p):
    C = 3.0e4                                   # f(h) = f0 + C h^p
    f = [C * x ** p for x in h]                 # coarse to fine; the exact value is f0 (0 here)
    e32, e21 = abs(f[0] - f[1]), abs(f[1] - f[2])
    band, order = gci(e21, e32, h[1] / h[2], h[0] / h[1])
    assert order == pytest.approx(p, rel=1e-6)
    assert band == pytest.approx(SAFETY * f[2], rel=1e-6)      # the fine level's true error, × F_s


def test_no_fall_no_band_and_the_order_is_capped():
    assert gci(0.4, 0.3, 1.33, 1.33) == (math.inf, pytest.approx(math.nan, nan_ok=True))
    assert gci(0.0, 0.0, 1.33, 1.33)[0] == 0.0
    band, order = gci(0.1, 10.0, 4 / 3, 4 / 3)                # apparent p = 16: credited P_MAX only
    assert order == P_MAX and band == pytest.approx(SAFETY * 0.1 / ((4 / 3) ** 2 - 1))
    out = gci_by_depth([0.1, 0.2], [0.2, 0.1], (0.008, 0.006, 0.0045))
    assert out["ratios"] == pytest.approx([4 / 3, 4 / 3]) and math.isinf(out["gci_px"][1])


def test_bad_values_name_the_argument():
    with pytest.raises(ValueError, match="e21"):
        gci(-1.0, 1.0, 1.3, 1.3)
    with pytest.raises(ValueError, match="r32"):
        gci(1.0, 2.0, 1.3, 1.0)
