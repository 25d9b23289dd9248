"""The reference's finger (flexsheet/fem/reference/capsule_contact.py): the capsule's gap, bad input
refused."""


import numpy as np
import pytest

from flexsheet.fem.reference import capsule_contact as CC


def test_capsule_gap_sphere_and_shaft():
    c = CC.capsule_at(0.0, 0.010, 0.008, 0.035, np.array([-0.035, 0.0, 0.0]))
    assert np.allclose(c.direction, [-1, 0, 0]) and np.allclose(c.center, [-0.010 + 0.008, 0, 0])
    g, n = c.gap(np.array([[-0.010, 0.0, 0.0], [-0.002, 0.0, 0.009], [0.05, 0.0, 0.0085]]))
    assert abs(g[0]) < 1e-12 and np.allclose(n[0], [-1, 0, 0])        # leading point on the sphere
    assert abs(g[1] - 0.001) < 1e-12 and np.allclose(n[1], [0, 0, 1])  # beside the sphere centre
    assert abs(g[2] - 0.0005) < 1e-12                                  # beside the shaft, 50 mm back


@pytest.mark.parametrize("bad, word", [(dict(depth=-0.001), "depth"), (dict(depth=float("nan")), "depth"),
                                       (dict(angle=float("inf")), "angle"), (dict(radius=0.0), "radius")])
def test_capsule_rejects_bad_input(bad, word):
    args = dict(angle=0.0, depth=0.01, radius=0.008, cyl_radius=0.035, cyl_center=np.zeros(3)) | bad
    with pytest.raises(ValueError, match=word):
        CC.capsule_at(**args)
