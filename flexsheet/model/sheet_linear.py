"""The small-deflection (linear) membrane under a uniform pressure patch, by double Fourier series: the
closed-form check of :class:`flexsheet.model.sheet_fem.SheetFEM` at small loads. Units: m, N."""

from __future__ import annotations

import math

import numpy as np

from flexsheet.model.sheet_fem import SheetPhysics

__all__ = ["linear_patch_deflection"]


def linear_patch_deflection(physics: SheetPhysics, force: float, half_side: float, u, v, modes: int = 400
                            ) -> np.ndarray:
    """Small-deflection (linear) membrane under a uniform pressure patch, by double Fourier series — the
    reference the FEM is checked against at small load (an independent closed form).

    T_u w_uu + T_v w_vv = −p on |u| ≤ a, |v| ≤ b; w = 0 at u = ±a; w_v = 0 at v = ±b; p = force/(2c)² on
    |u|, |v| ≤ c (c = ``half_side``, centred). Modes sin(kπ(u + a)/2a)·cos(mπ(v + b)/2b), k = 1…``modes``,
    m = 0…``modes``. Returns w (m) at (u, v) (broadcast). Source: separation of variables, e.g. Timoshenko &
    Woinowsky-Krieger §29 (Navier/Lévy series) for the membrane operator. Uniform pre-stress only: raises
    ``ValueError`` for the gripped field (``physics.tension_ratio`` None).
    """
    if physics.gripped:
        raise ValueError("tension_ratio must be a number (a uniform pre-stress) for the linear series, got "
                         "None")
    a, b, c = physics.half_span, physics.half_width, float(half_side)
    Tu, Tv = physics.tension_u, physics.tension_ratio * physics.tension_u
    p = force / (2 * c) ** 2
    k = np.arange(1, modes + 1)
    m = np.arange(0, modes + 1)
    lam = k * math.pi / (2 * a)
    nu_ = m * math.pi / (2 * b)
    Iu = (np.cos(lam * (a - c)) - np.cos(lam * (a + c))) / lam
    with np.errstate(divide="ignore", invalid="ignore"):
        Iv = np.where(m == 0, 2 * c,
                      (np.sin(nu_ * (b + c)) - np.sin(nu_ * (b - c))) / np.where(m == 0, 1, nu_))
    normv = np.where(m == 0, 2 * b, b)
    W = (p * Iu[:, None] * Iv[None, :] / (a * normv[None, :])
         / (Tu * lam[:, None] ** 2 + Tv * nu_[None, :] ** 2))
    u, v = np.broadcast_arrays(np.asarray(u, float), np.asarray(v, float))
    su = np.sin(lam[None, :] * (u.ravel()[:, None] + a))
    cv = np.cos(nu_[None, :] * (v.ravel()[:, None] + b))
    return np.einsum("nk,km,nm->n", su, W, cv).reshape(u.shape)
