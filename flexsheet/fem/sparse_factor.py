"""Sparse factorisation of symmetric positive-definite matrices (pure): :func:`factor` (CHOLMOD's supernodal
Cholesky through scikit-sparse, or SuperLU), and :class:`NotPositiveDefinite` when CHOLMOD meets a
non-positive pivot. The linear models' solves (:mod:`flexsheet.fem.solver`, :mod:`flexsheet.fem.corotational`)
and the nonlinear reference's Newton steps (:mod:`flexsheet.fem.reference.newton`) factorise with it."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

__all__ = ["NotPositiveDefinite", "factor"]


class NotPositiveDefinite(ValueError):
    """:func:`factor` met a non-positive pivot: the matrix is not positive definite."""


class _Cholesky:
    """Sparse Cholesky of a symmetric positive-definite matrix (CHOLMOD, supernodal, through scikit-sparse;
    Chen, Davis, Hager & Rajamanickam, ACM TOMS 35, 2008); ``solve(b)`` for (n,) or (n, k). Raises
    :class:`NotPositiveDefinite` at a non-positive pivot (nothing is kept: cholespy, used before, leaked its
    factor, ~0.5 GB each time, on that path)."""

    __slots__ = ("_f",)

    def __init__(self, A: sp.spmatrix):
        from sksparse.cholmod import CholmodNotPositiveDefiniteError, cholesky

        why = None
        try:
            # supernodal always: CHOLMOD's simplicial mode (what "auto" picks for very sparse matrices) is an
            # LDLᵀ that factorises an indefinite matrix without complaint
            self._f = cholesky(sp.csc_matrix(A), mode="supernodal")
        except CholmodNotPositiveDefiniteError as exc:
            why = str(exc)      # raised below, outside the handler: no __context__ holding the failed factor
        if why is not None:
            raise NotPositiveDefinite(why)

    def solve(self, b: np.ndarray) -> np.ndarray:
        """x with A x = b; ``b`` (n,) or (n, k)."""
        return self._f(np.ascontiguousarray(b, np.float64))


def factor(A: sp.spmatrix, backend: str = "auto"):
    """Factorise a symmetric positive-definite sparse matrix; returns an object with ``.solve(b)``.

    ``backend``: "cholmod" (CHOLMOD's supernodal Cholesky via scikit-sparse, 5–10× faster here), "superlu"
    (scipy ``splu`` with a symmetric ordering) or "auto" (CHOLMOD when importable, else SuperLU). Raises
    ``ValueError`` on an unknown backend and :class:`NotPositiveDefinite` (CHOLMOD) when A is not positive
    definite."""
    if backend not in ("auto", "cholmod", "superlu"):
        raise ValueError(f"backend must be 'auto', 'cholmod' or 'superlu', got {backend!r}")
    if backend in ("auto", "cholmod"):
        try:
            return _Cholesky(A)
        except ImportError:
            if backend == "cholmod":
                raise
    return spla.splu(sp.csc_matrix(A), permc_spec="MMD_AT_PLUS_A", options={"SymmetricMode": True})
