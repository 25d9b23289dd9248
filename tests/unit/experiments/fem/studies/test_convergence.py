"""The reference's convergence study and the studies beside it
(flexsheet/experiments/fem/studies/convergence.py) in the quick run: the reference's physics (force rising
with depth, the Hertz force at a shallow push, no element inverted at a quadrature point), the skin study and
the penalty study."""

import json
import math

import numpy as np
import pytest

# the first test of the package's quick run sets it up (conftest.py: a subprocess of several minutes cold,
# timeout 1500 s in _run): pytest-timeout counts fixture setup in that test's 300 s default
pytestmark = [pytest.mark.timeout(1500), pytest.mark.slow]   # and the slow tier (tests/run.sh --slow)


def test_reference_physics(quick):
    base, s, _ = quick
    with open(base / "out" / "convergence.json") as fh:
        conv = json.load(fh)
    depths = conv["depths_m"]
    assert depths[-1] == pytest.approx(0.05)
    for lv in conv["levels"]:
        f = lv["force_N"]
        assert all(b > a for a, b in zip(f, f[1:], strict=False)), f  # stiffer the deeper, no snap back
        assert max(lv["inverted_qp"]) == 0  # the line search keeps det F > 0
        assert lv["newton_converged"]
    # Hertz (Johnson, Contact Mechanics §4.2) at the shallowest
    # push: sphere r = 8 mm on the R = 35.4 mm cylinder
    E, nu, r, R = s["material"]["E"], s["material"]["nu"], s["finger_radius_m"], 0.025 * math.sqrt(2)
    d = depths[0]
    r_eff = math.sqrt(r * (r * R / (r + R)))
    hertz = 4.0 / 3.0 * E / (1 - nu ** 2) * math.sqrt(r_eff) * d ** 1.5
    assert conv["levels"][-1]["force_N"][0] == pytest.approx(hertz, rel=0.25)
    # the coarser mesh differs from the finest, by less than a centimetre on the visible surface
    err = conv["levels"][0]["error_vs_finest_mm"]
    assert 0 < max(err) < 10
    assert max(conv["levels"][-1]["error_vs_finest_mm"]) == 0
    ref = s["reference"]
    assert ref["mesh_converged"] == (ref["monotone_decrease"] and ref["last_refinement_change_mm"] <= 0.35
                                     and ref["finest_newton_converged"]
                                     and ref["finest_inverted_qp_max"] == 0)
    assert ref["converged"] == (ref["mesh_converged"] and ref["penalty_study"]["converged"])
    if len(conv["levels"]) < 3:
        assert not ref["converged"]


def test_skin_study_refines_the_surface_layer_only(quick):
    """The skin study's variant is the next-to-finest mesh plus a finer surface layer: more DOF than that
    mesh, Newton converged, a real change of the visible surface at every depth past the first, and a softer
    push at 50 mm (finer elements where the finger bends the surface stiffen it less; the full tube refinement
    does too)."""
    base, s, _ = quick
    with open(base / "out" / "convergence.json") as fh:
        conv = json.load(fh)
    sk = conv["skin_study"]
    assert (sk["unrefined"]["h_fine"] == conv["levels"][-2]["h_fine_m"]
            and sk["unrefined_dofs"] == conv["levels"][-2]["dofs"])
    (row,) = sk["skins"]
    assert row["spec"]["skin_h"] == 0.005 and row["newton_converged"] and row["dofs"] > sk["unrefined_dofs"]
    ch = np.array(row["change_vs_unrefined_mm"])
    assert ch.shape == (len(sk["depths_m"]),) and np.all(np.isfinite(ch)) and np.all(ch[1:] > 0.01)
    f0, f_fine = sk["unrefined_force_N_at_50mm"], sk["finest_force_N_at_50mm"]
    assert f_fine < f0 and row["force_N_at_50mm"] < f0 - 0.1, (f0, row["force_N_at_50mm"], f_fine)
    assert s["reference"]["skin_study"]["skins"][0]["change_vs_unrefined_mm_at_50mm"] == pytest.approx(ch[-1])


def test_penalty_study_shows_the_default_penalty_converged(quick):
    """The contact penalty is a discretisation parameter too: a 10× stiffer finger penetrates less and moves
    the visible surface by less than 0.1 mm at the default; the default penetrates the finger by < 0.05 mm at
    50 mm (the old 10³·E/h penetrated 1.2 mm there)."""
    base, s, _ = quick
    with open(base / "out" / "convergence.json") as fh:
        pen = json.load(fh)["penalty_study"]
    rows = {r["penalty_scale"]: r for r in pen["scales"]}
    d, stiff = pen["default_scale"], 10 * pen["default_scale"]
    assert set(rows) == {d, stiff}
    assert rows[d]["penetration_mm_at_50mm"] < 0.05
    assert rows[stiff]["penetration_mm_at_50mm"] <= rows[d]["penetration_mm_at_50mm"]
    assert 0 < pen["default_vs_10x_stiffer_mm"] == pytest.approx(max(rows[d]["error_vs_stiffest_mm"]))
    assert pen["converged"] == (pen["default_vs_10x_stiffer_mm"] <= pen["tolerance_mm"] == 0.1)
    assert pen["converged"]
    # a stiffer finger pushes back harder, by little once converged
    assert rows[stiff]["force_N_at_50mm"] == pytest.approx(rows[d]["force_N_at_50mm"], rel=0.01)
    assert all(r["newton_converged"] for r in pen["scales"])
