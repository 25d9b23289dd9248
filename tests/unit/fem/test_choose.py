"""The model choice (flexsheet/fem/choose.py): the cheapest mesh meeting the accuracy target, the shipped
table's choice, linear where it suffices and the snapshots where it does not."""

import pytest

from flexsheet.fem.choose import Choice, choose, choose_fem_model
from flexsheet.fem.material import Material

MAT = Material()


def test_choose_takes_cheapest_meeting_target():
    def entry(h, hf, order, dofs, err):
        return {"spec": {"h": h, "h_fine": hf, "refine_radius": 0.012, "arc_deg": 0.0}, "order": order,
                "mesh_nodes": dofs // 3, "dofs": dofs, "surface_error_m": {"0.0050": err / 2, "0.0300": err}}

    table = {"nu": 0.45, "finger_radius": 0.008, "candidates": [
        entry(0.012, 0.006, 1, 1000, 0.003), entry(0.012, 0.004, 2, 9000, 0.0006),
        entry(0.010, 0.004, 2, 15000, 0.0005), entry(0.008, 0.003, 1, 4000, 0.0009)]}
    ch = choose(table, 0.0007, 0.005, 0.03, 0.45, 0.008)
    assert (isinstance(ch, Choice) and ch.met and ch.order == 2 and ch.spec.h_fine == 0.004
            and ch.spec.h == 0.012)
    ch = choose(table, 0.001, 0.005, 0.03, 0.45, 0.008)
    assert ch.met and ch.order == 1 and ch.spec.h == 0.008
    ch = choose(table, 0.0001, 0.005, 0.03, 0.45, 0.008)
    assert not ch.met and ch.spec.h == 0.010
    assert not choose(table, 0.0007, 0.005, 0.03, 0.3, 0.008).met      # table made for another nu
    with pytest.raises(ValueError, match="target"):
        choose(table, -1.0, 0.0, 0.03, 0.45, 0.008)


def test_shipped_table_gives_a_choice_meeting_the_default_target():
    from flexsheet.fem.choose import load_table

    ch = choose(load_table(), 0.0007, 0.005, 0.03, MAT.nu, 0.008)
    assert ch.met and ch.error <= 0.0007


def test_choose_model_prefers_linear_where_it_suffices():
    table = {"candidates": [
        {"kind": "linear", "name": "lin", "update_ms": 0.6,
         "max_error_m_by_depth": {"0.0050": 0.0003, "0.0300": 0.004, "0.0500": 0.012}},
        {"kind": "snapshots", "name": "snap", "update_ms": 0.3,
         "max_error_m_by_depth": {"0.0050": 0.0002, "0.0300": 0.0004, "0.0500": 0.0006}}]}
    assert choose_fem_model(table, 0.0007, 0.005)[0] == "linear"
    assert choose_fem_model(table, 0.0007, 0.05)[0] == "snapshots"
    kind, why = choose_fem_model(table, 0.0001, 0.05)
    assert kind == "snapshots" and "no model meets" in why
    assert choose_fem_model(None, 0.0007, 0.05)[0] == "snapshots"
    with pytest.raises(ValueError, match="depth_max"):
        choose_fem_model(table, 0.0007, float("nan"))
