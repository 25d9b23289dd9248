"""The one sparse Cholesky (flexsheet/fem/sparse_factor.py) of the linear model and the nonlinear
reference."""

import numpy as np
import pytest


def test_cholesky_solves_spd_systems_and_refuses_an_indefinite_matrix_without_keeping_it():
    """The one sparse Cholesky (CHOLMOD via scikit-sparse) of the linear model and of the nonlinear reference:
    it solves an SPD system (one and several right-hand sides) to rounding, and an indefinite matrix is a
    NotPositiveDefinite error, which the reference reads as "take the projected tangent" (None)."""
    import scipy.sparse as sp

    from flexsheet.fem.reference.newton import cholesky_or_none
    from flexsheet.fem.sparse_factor import NotPositiveDefinite, factor

    n = 400
    lap = sp.diags([-np.ones(n - 1), 2.05 * np.ones(n), -np.ones(n - 1)], [-1, 0, 1], format="csr")
    b = np.random.default_rng(3).standard_normal((n, 2))
    x = factor(lap, "cholmod").solve(b)
    assert np.abs(lap @ x - b).max() < 1e-10
    assert np.allclose(factor(lap, "cholmod").solve(b[:, 0]), x[:, 0], atol=1e-12)
    assert np.allclose(factor(lap, "superlu").solve(b[:, 0]), x[:, 0], atol=1e-10)
    bad = (lap - 0.2 * sp.identity(n)).tocsr()          # smallest eigenvalue 0.05 - 0.2 < 0
    with pytest.raises(NotPositiveDefinite) as err:
        factor(bad, "cholmod")
    # nothing refers to the failed factor
    assert err.value.__context__ is None and err.value.__cause__ is None
    assert cholesky_or_none(bad) is None
    fac = cholesky_or_none(lap)
    assert np.abs(lap @ fac.solve(b[:, 1]) - b[:, 1]).max() < 1e-10
    with pytest.raises(ValueError, match="backend"):
        factor(lap, "mumps")
