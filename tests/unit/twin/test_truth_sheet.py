"""The twin's true sheet from one table family (flexsheet/twin/truth_sheet.py): modulus and thickness scale
the FEM's force exactly, pre-strain and grip slip shift its strain, the interpolation is exact on the forms it
is built for, a missing table is an error naming the command that ships it, and against full FEM solves of
three drawn truths the force is within 2 % (slow tier)."""

from __future__ import annotations

import numpy as np
import pytest

from flexsheet.model.sheet import clamp_half_span
from flexsheet.model.sheet_fem import SheetFEM, SheetPhysics
from flexsheet.model.tension import SheetMaterial, tension
from flexsheet.twin import truth_sheet as ts
from flexsheet.twin.truth_sheet import (
    A_STRAINS,
    B_STRAINS,
    E0,
    FORCE_DEPTHS,
    SPAN_OFFSET,
    T0,
    TruthSheet,
    load_family,
    node_path,
)

COARSE = {"h_fine": 0.012, "h_coarse": 0.02}


def _physics(young: float, thickness: float, strain: float, span_strain: float) -> SheetPhysics:
    mat = SheetMaterial(young=young, thickness=thickness)
    return SheetPhysics(half_span=clamp_half_span(span_strain), young=young, thickness=thickness,
                        tension_u=tension(strain, mat), tension_ratio=None)


def test_modulus_and_thickness_scale_the_fem_force_exactly_and_leave_the_shape():
    depths = [0.005, 0.015, 0.030]
    nominal = SheetFEM(_physics(E0, T0, 0.05, 0.05), **COARSE).solve_indent(depths, 0.036, 0.0)
    drawn = SheetFEM(_physics(1.3 * E0, 0.95 * T0, 0.05, 0.05), **COARSE).solve_indent(depths, 0.036, 0.0)
    for a, b in zip(nominal, drawn, strict=True):
        assert b.force / a.force == pytest.approx(1.3 * 0.95, rel=2e-4)  # only the contact penalty is fixed
        assert np.abs(b.w - a.w).max() < 2e-6                                 # m
    assert nominal[-1].force > 5.0 * nominal[0].force                         # the forces are not trivial


def _fake_family(folder, alpha, cubic, span_gain) -> None:
    """Family tables whose force is F = α(ε)·d + c·d³ (layer A) and (1 + span_gain)·F (layer B)."""
    P = len(ts.TABLE_POSITIONS)
    d = np.asarray(FORCE_DEPTHS)
    for lay, strains in (("A", A_STRAINS), ("B", B_STRAINS)):
        for e in strains:
            Fd = np.broadcast_to(alpha(e) * d + cubic * d ** 3, (P, P, d.size)).copy()
            Fd *= 1.0 + np.arange(P)[:, None, None] * 0.1                    # stiffer toward the clamp
            Fd *= 1.0 + (span_gain if lay == "B" else 0.0)
            span = e + (SPAN_OFFSET if lay == "B" else 0.0)
            np.savez(node_path(lay, e, str(folder)), x=np.zeros(2), y=np.zeros(2),
                     W=np.zeros((P, P, 5, 2, 2)),
                     F=Fd[:, :, :5], Fd=Fd, strain=e, span_strain=span, key=ts.family_key())


def test_the_truth_sheet_scales_shifts_and_interpolates_a_known_family_exactly(tmp_path):
    alpha = lambda e: 20.0 + 300.0 * e - 200.0 * e * e + 150.0 * e ** 3       # noqa: E731  cubic in ε: N/m
    _fake_family(tmp_path, alpha, 4.0e4, -0.06)
    folder = str(tmp_path)
    nominal = TruthSheet(E0, T0, 0.0, 0.0, folder)
    for d in (0.0007, 0.004, 0.0123, 0.029):                                   # off the table's depths
        for s in (0.0037, 0.05, 0.173, 0.29):                                    # off its strains
            want = alpha(s) * d + 4.0e4 * d ** 3
            assert nominal.force(d, 0.0, 0.0, s) == pytest.approx(want, rel=1e-9)
            assert nominal.force(d, -0.054, 0.018, s) == pytest.approx(1.15 * want, rel=1e-9)  # bilinear in u
    drawn = TruthSheet(1.2 * E0, 0.9 * T0, 0.004, 0.05, folder)
    s = 0.12
    eps = s * 0.95 + 0.004
    assert drawn.strain(s) == pytest.approx(eps)
    gain = 1.0 - 0.06 * (s - eps) / SPAN_OFFSET                                 # the span 0.002 above ε's own
    assert drawn.force(0.01, 0.0, 0.0, s) == pytest.approx(1.08 * gain * (alpha(eps) * 0.01 + 0.04), rel=1e-9)
    slack = TruthSheet(E0, T0, 0.003, 0.05, folder)                             # clamps closer than the sheet
    assert slack.force(0.01, 0.0, 0.0, -0.02) == slack.force(0.01, 0.0, 0.0, 0.0)
    assert slack.force(0.01, 0.0, 0.0, 0.0) == pytest.approx((alpha(0.003) * 0.01 + 0.04) * (1 - 0.06 * -0.1),
                                                               rel=1e-9)
    k = nominal.stiffness(0.02, 0.0, 0.0, 0.05)
    assert k == pytest.approx(alpha(0.05) + 3 * 4.0e4 * 0.02 ** 2, rel=1e-3)     # dF/dd, N/m
    assert nominal.force(0.0, 0.0, 0.0, 0.05) == 0.0


def test_a_missing_table_is_an_error_naming_the_command_that_ships_it(tmp_path):
    _fake_family(tmp_path, lambda e: 10.0, 0.0, 0.0)
    gone = node_path("B", B_STRAINS[1], str(tmp_path))
    (tmp_path / gone.split("/")[-1]).unlink()
    with pytest.raises(FileNotFoundError, match=r"lacks 1 of 15 tables: .*truth_sheet --ship.*\(missing: "
                                                r"B0\.04\)"):
        load_family(str(tmp_path))


def test_the_shipped_family_is_whole_and_reads_its_own_tables_at_their_strains():
    fam = load_family()
    sheet = TruthSheet(E0, T0, 0.0, 0.0)
    for tab in fam["A"][3::4]:
        for i, j, k in ((0, 0, 6), (1, 2, 10), (2, 0, 3)):
            u, v = ts.TABLE_POSITIONS[i], ts.TABLE_POSITIONS[j]
            assert sheet.force(FORCE_DEPTHS[k], u, v, tab.strain) == pytest.approx(tab.Fd[i, j, k], rel=1e-12)
    f = [sheet.force(0.01, 0.0, 0.0, s) for s in np.linspace(0.0025, 0.30, 596)]
    assert np.all(np.diff(f) > 0.0)                                             # stiffer with the pull
    for e in A_STRAINS[1:-1]:  # no step where the windows change
        below, above = sheet.force(0.01, 0.0, 0.0, e - 1e-7), sheet.force(0.01, 0.0, 0.0, e + 1e-7)
        assert abs(above / below - 1.0) < 1e-4
    assert 0.05 < f[0] < f[-1] < 5.0                                            # N at 10 mm


@pytest.mark.slow
def test_the_truth_sheet_is_within_2_percent_of_the_full_fem_on_three_drawn_truths():
    out = ts.check(ts.check_seeds(), depths=(0.002, 0.008, 0.017, 0.030), bins=ts.CHECK_BINS[1::2],
                   off_grid=False)
    errs = [abs(r["error_pct"]) for r in out["points"]]
    assert len(errs) == 3 * 2 * 4 and max(errs) < 2.0, out["worst_pct"]
