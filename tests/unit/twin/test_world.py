"""The twin's true force between its clamp-strain tables (flexsheet/twin/world.py): interpolated, so the judge
measures the display and not the simulator's steps between tables."""

from __future__ import annotations

import numpy as np

from flexsheet.model.sheet_table import FemShape
from flexsheet.twin.truth import TwinTruth
from flexsheet.twin.world import TruePhysics


class _Table:
    """A table at one clamp-strain node whose force rises with the node (as a stretched sheet's does)."""

    def __init__(self, node: float) -> None:
        self.node = node

    def shape(self, depth, push_u, push_v, half_span):
        return FemShape(table=self, half_span=half_span, half_width=0.12, push_u=push_u, push_v=push_v,
                        depth=depth, force=1000.0 * depth * (1.0 + 30.0 * self.node), stiffness=1000.0 * (1.0 + 30.0 * self.node))


def _physics(nodes) -> TruePhysics:
    phys = TruePhysics(TwinTruth.draw(0, "ideal"))
    phys.tables = {n: _Table(n) for n in nodes}
    return phys


def _force(phys: TruePhysics, strain: float) -> float:
    return phys.shape(0.01, 0.0, 0.0, 0.5 * phys.size * (1.0 + strain)).force


def test_the_true_force_is_continuous_across_the_midpoint_between_two_tables():
    phys = _physics([0.01, 0.02])
    below, above = _force(phys, 0.01499), _force(phys, 0.01501)
    assert abs(above - below) / below < 1e-3              # nearest-table look-up stepped 23 % here
    assert np.isclose(_force(phys, 0.015), 0.5 * (_force(phys, 0.01) + _force(phys, 0.02)))
    assert np.isclose(_force(phys, 0.01), 10.0 * 1.3) and np.isclose(_force(phys, 0.02), 10.0 * 1.6)
    only = _physics([0.01])                              # the other node not loaded yet: the nearest alone
    assert np.isclose(_force(only, 0.0149), 13.0) and np.isclose(_force(only, 0.0151), 13.0)


def test_a_loaded_node_asks_for_its_neighbour_and_a_slack_sheet_for_node_zero():
    phys = _physics([0.01, 0.02])
    assert phys.bracket(0.013) == (0.01, 0.02, phys.bracket(0.013)[2]) and np.isclose(phys.bracket(0.013)[2], 0.3)
    assert phys.bracket(-0.02) == (0.0, 0.01, 0.0)
    assert phys.missing_node(0.013) is None and phys.missing_node(0.017) is None
