"""How hard an arm may pull the sheet at a pose: the joint torques Jᵀ·F of the sheet's pull against the
RV-1A's limits (pure: numpy + the arm's Pinocchio kinematics).

The sheet pulls each clamp toward the sheet's centre along ``axis_u`` (the clamp frame's second axis, sheet
convention of :mod:`flexsheet.model.geometry`) with the clamp force F (N,
:func:`flexsheet.model.tension.clamp_force`). At the clamp frame that is the wrench w = (f, 0), f = (0, −F, 0)
for the left clamp (+axis_u side) and (0, +F, 0) for the right; its joint torques are τ = Jᵀ w with J the
clamp frame's geometric Jacobian (:meth:`flexsheet.arm.kinematics.ArmKinematics.jacobian`, ``pin.LOCAL``). τ
is linear in F, so the largest pull the pose allows is min over joints of τ_lim,j / |τ_j(1 N)|.

**Torque limits** (:data:`TORQUE_LIMITS`, N·m; assumptions, flagged): Mitsubishi rates the RV-1A for a 1 kg
payload; its manuals say a force on the flange is bounded by the joint torques and allowable wrist moments at
the pose, not by the payload read as a force. The per-joint torque figures are not published to us, so each
limit is the largest static torque the rated 1 kg at the clamp point loads that joint with anywhere in the
joint limits (20 000 sampled poses of ``rv1a.urdf``): J2 5.07, J3 2.80, J4 1.00, J5 1.00 N·m — a joint the
payload cannot load (J1 about the vertical, J6 about the tool axis) takes its neighbour's figure (J1 = J2, J6
= J5). The arm's own links' weight is the controller's to carry and is not counted against them. Measure the
real figures (the controller's load monitor, or the maker's data) before trusting a pull near the limit.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["TORQUE_LIMITS", "joint_torques", "max_pull"]

#: joint torque limits, N·m, J1…J6 (module doc: assumptions from the rated 1 kg payload at its worst pose)
TORQUE_LIMITS = np.array([5.07, 5.07, 2.80, 1.00, 1.00, 1.00])


def joint_torques(kin, q, pull: float) -> np.ndarray:
    """τ (6,) N·m at joints ``q`` (6,) rad of arm ``kin`` (:class:`~flexsheet.arm.kinematics.ArmKinematics`)
    for the sheet pulling its clamp with ``pull`` N toward the sheet's centre (module doc). Raises
    ``ValueError`` for a bad ``q`` or a negative or non-finite pull."""
    if not (math.isfinite(pull) and pull >= 0.0):
        raise ValueError(f"pull must be finite and >= 0 N, got {pull!r}")
    J = kin.jacobian(q)
    sign = -1.0 if kin.side == "left" else 1.0
    return J[1] * (sign * pull)                    # Jᵀ (0, ±F, 0, 0, 0, 0): row 1 of J is the axis_u force's


def max_pull(kin, q, limits=TORQUE_LIMITS) -> tuple[float, int]:
    """(largest pull N the pose allows, the 1-based joint that sets it) at joints ``q`` (module doc);
    (inf, 0) where no joint is loaded. Raises ``ValueError`` for a bad ``q`` or limits that are not (6,)
    positive."""
    lim = np.asarray(limits, float)
    if lim.shape != (6,) or not (lim > 0.0).all():
        raise ValueError(f"limits must be (6,) positive N·m, got {limits!r}")
    per_newton = np.abs(joint_torques(kin, q, 1.0))
    with np.errstate(divide="ignore"):
        f = np.where(per_newton > 1e-12, lim / per_newton, np.inf)
    j = int(np.argmin(f))
    return (float(f[j]), j + 1) if math.isfinite(f[j]) else (math.inf, 0)
