"""RV-1A kinematics for the sheet-clamp tool frame: FK, seeded damped-least-squares IK, manipulability.

Pure module (numpy + Pinocchio, no I/O besides reading the packaged URDF once). The robot model is
``rv1a.urdf`` beside this file (sources cited in its header). Frames:

- ``base``: the arm's base frame (URDF ``base_link``), placed in the ``display`` frame by ``T_display_base``
  built from (x, y, z, yaw) with :func:`flexsheet.model.geometry.pose_matrix`.
- tool: the sheet clamp, in the sheet convention of :mod:`flexsheet.model.geometry` (columns of R are
  (normal, axis_u, axis_v), origin at the middle of the clamped edge). The URDF ``clamp`` link is that frame
  for the left clamp; for the right clamp the sheet frame is the ``clamp`` link turned by pi about its x axis
  (axis_u points from the right clamp inward).

Joint vector ``q``: (6,) float64, rad, J1..J6, URDF convention (J3 = pi/2 with the forearm square to the
upper arm, as in the source model).

IK (:meth:`ArmKinematics.ik`): damped least squares on the SE(3) error ``log6(T(q)^-1 T_target)`` (body
frame), Jacobian from Pinocchio (``LOCAL``), with the damping raised near singularities
(Nakamura & Hanafusa 1986; Chiaverini 1997 form ``lambda^2 = lambda_max^2 (1 - (w/w0)^2)`` for ``w < w0``),
each step capped and projected onto the joint limits. It is seeded from the current joints, so it
follows the branch the arm is on and never flips configuration. It stops short and reports rather than
jumping: the result carries ``ok`` and a ``status`` (``"ok"``, ``"unreachable"``, ``"limit:J<k>"``,
``"singular"``, ``"jump"``). Source of the method: Siciliano et al., *Robotics: Modelling, Planning and
Control*, §3.7; Buss, "Introduction to inverse kinematics with Jacobian transpose, pseudoinverse and damped
least squares" (2004).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pinocchio as pin

from flexsheet.model.checks import check_pose
from flexsheet.model.geometry import pose_matrix
from flexsheet.model.vec import vnorm

__all__ = ["URDF_PATH", "JOINT_NAMES", "Q_LOWER", "Q_UPPER", "QD_MAX", "DATASHEET_SPEED_DEG", "Q_HOME",
           "home_joints", "IKResult", "ArmKinematics", "clamp_joints", "outside_limits", "rotation_angle"]

URDF_PATH = Path(__file__).with_name("rv1a.urdf")
JOINT_NAMES = ("J1", "J2", "J3", "J4", "J5", "J6")

_MODEL = pin.buildModelFromUrdf(str(URDF_PATH))
Q_LOWER = np.array(_MODEL.lowerPositionLimit, dtype=float)   #: (6,) rad, URDF lower limits
Q_UPPER = np.array(_MODEL.upperPositionLimit, dtype=float)   #: (6,) rad, URDF upper limits
#: (6,) rad/s, the RV-1A datasheet's maximum joint speeds J1..J6 = 180, 90, 135, 180, 180, 210 deg/s (URDF
#: ``velocity``; Mitsubishi BFP-A8050, see the URDF header). The bridge commands ``speed_scale`` × these.
QD_MAX = np.array(_MODEL.velocityLimit, dtype=float)
#: the datasheet values the URDF must carry, deg/s (checked by tests/unit/arm/test_kinematics.py)
DATASHEET_SPEED_DEG = (180.0, 90.0, 135.0, 180.0, 180.0, 210.0)
# LEFT_BASE / RIGHT_BASE: the base poses (x, y, z, yaw) in the display frame (m, rad), defined once in
# flexsheet.model.geometry and re-exported here (the arm bridge imports them from this module). They reach the
# home sheet and tilts of +-60 deg about the cylinder axis with stretch 0..0.1 with >= 20 deg joint margin.
#: left arm's joints (rad) holding the home sheet (stretch 0) from LEFT_BASE; the right arm mirrors it
Q_HOME = np.radians([8.67, 42.46, 104.28, 10.33, -57.17, 84.35])
_MIRROR = np.array([-1.0, 1.0, 1.0, -1.0, 1.0, -1.0])


def home_joints(side: str) -> np.ndarray:
    """(6,) rad: joints holding the home sheet from the proposed base of ``side`` ("left"/"right").

    The right arm mirrors the left across the display x–z plane: q_right = q_left · (−1, 1, 1, −1, 1, −1).
    Raises ``ValueError`` on another side.
    """
    if side not in ("left", "right"):
        raise ValueError(f"side must be 'left' or 'right', got {side!r}")
    return Q_HOME.copy() if side == "left" else Q_HOME * _MIRROR

_FLIP_X = np.diag([1.0, -1.0, -1.0, 1.0])   # rotation by pi about x (homogeneous)


def rotation_angle(R_a: np.ndarray, R_b: np.ndarray) -> float:
    """Angle (rad) of the relative rotation R_aᵀ R_b between two (3, 3) rotations."""
    c = (float(np.trace(R_a.T @ R_b)) - 1.0) * 0.5
    return math.acos(max(-1.0, min(1.0, c)))


@dataclass(frozen=True)
class IKResult:
    """Outcome of :meth:`ArmKinematics.ik`.

    ``q`` (6,) rad: the solution when ``ok``; otherwise the best joint vector found, within the limits
    (callers must not command it blindly — the bridge holds instead). ``ok``: converged within tolerance,
    within limits, not singular, no jump. ``status``: "ok", "unreachable", "limit:J<k>", "singular" or "jump".
    ``pos_err`` m and ``rot_err`` rad: residual at ``q``. ``iterations``: DLS iterations used.
    ``manipulability``: Yoshikawa's measure at ``q``.
    """

    q: np.ndarray
    ok: bool
    status: str
    pos_err: float
    rot_err: float
    iterations: int
    manipulability: float


class ArmKinematics:
    """FK/IK of one RV-1A holding one sheet clamp, expressed in the ``display`` frame.

    Parameters
    ----------
    side : "left" or "right"
        Which sheet edge the arm holds (decides the clamp-frame flip, see module doc).
    base : (x, y, z, yaw) in m, m, m, rad, or a (4, 4) transform T_display_base.
    q_lower, q_upper : (6,) rad, optional
        Joint limits used by IK (default: the URDF's). A margin may be applied by the caller.

    Raises ``ValueError`` on a bad side or base. Not thread-safe (one Pinocchio ``Data`` per instance).
    """

    def __init__(self, side: str, base=(0.0, 0.0, 0.0, 0.0), q_lower=None, q_upper=None) -> None:
        if side not in ("left", "right"):
            raise ValueError(f"side must be 'left' or 'right', got {side!r}")
        self.side = side
        b = np.asarray(base, dtype=float)
        if b.shape == (4,):
            if not np.isfinite(b).all():
                raise ValueError(f"base must be finite, got {b!r}")
            self.T_display_base = pose_matrix(*b)
        else:
            self.T_display_base = check_pose("base", b)
        self.T_base_display = np.linalg.inv(self.T_display_base)
        self.model = _MODEL
        self.data = self.model.createData()
        self.fid = self.model.getFrameId("clamp")
        self.T_link_tool = _FLIP_X if side == "right" else np.eye(4)
        self.q_lower = Q_LOWER.copy() if q_lower is None else np.asarray(q_lower, dtype=float).copy()
        self.q_upper = Q_UPPER.copy() if q_upper is None else np.asarray(q_upper, dtype=float).copy()
        if self.q_lower.shape != (6,) or self.q_upper.shape != (6,) or (self.q_lower >= self.q_upper).any():
            raise ValueError(f"q_lower/q_upper must be (6,) with lower < upper, got {self.q_lower}, "
                             f"{self.q_upper}")
        # tool offset as a pin.SE3 so IK works in the URDF chain without per-iteration matrix products
        self._M_link_tool = pin.SE3(self.T_link_tool[:3, :3].copy(), self.T_link_tool[:3, 3].copy())
        self._M_tool_link = self._M_link_tool.inverse()
        # a clamp-frame twist in the URDF chain's link frame (the inverse of jacobian()'s action matrix)
        self._A_link_tool = self._M_link_tool.toActionMatrix()
        self._A_tool_link = self._M_tool_link.toActionMatrix()      # jacobian()'s, computed once

    # ------------------------------------------------------------------ forward kinematics
    def check_q(self, q) -> np.ndarray:
        """Return ``q`` as a (6,) float64 array; raise ``ValueError`` naming it if bad shape or not finite."""
        a = np.asarray(q, dtype=float)
        if a.shape != (6,) or not np.isfinite(a).all():
            raise ValueError(f"q must be a finite (6,) joint vector in rad, got {q!r}")
        return a

    def _link_pose(self, q: np.ndarray) -> pin.SE3:
        pin.framesForwardKinematics(self.model, self.data, q)
        return self.data.oMf[self.fid]

    def fk(self, q) -> np.ndarray:
        """T_display_clamp (4, 4), m, of joints ``q`` (6,) rad (sheet convention of
        :mod:`flexsheet.model.geometry`)."""
        q = self.check_q(q)
        return self.T_display_base @ self._link_pose(q).homogeneous @ self.T_link_tool

    def joint_origins(self, q) -> np.ndarray:
        """(8, 3) m, display frame: the chain's points at joints ``q`` (6,) rad, for link-level collision
        tests.

        Rows: the base origin, the origins of J1…J6 (Pinocchio ``data.oMi``, i.e. the URDF joint frames) and
        the clamp point (the tool-frame origin, the middle of the clamped edge = ``fk(q)[:3, 3]``).
        Consecutive rows bound the links; the J3→J4 row pair is the chord of the elbow's dog-leg offset
        (−0.090, 0, 0.043) m of ``rv1a.urdf``. Raises ``ValueError`` naming ``q`` if it is not a finite (6,)
        vector.
        """
        q = self.check_q(q)
        pin.framesForwardKinematics(self.model, self.data, q)
        local = np.empty((8, 3))
        local[0] = 0.0
        for i in range(1, 7):
            local[i] = self.data.oMi[i].translation
        local[7] = self.data.oMf[self.fid].translation
        return local @ self.T_display_base[:3, :3].T + self.T_display_base[:3, 3]

    def jacobian(self, q) -> np.ndarray:
        """(6, 6) geometric Jacobian of the clamp frame, rows (v, ω) in the clamp frame (``pin.LOCAL``)."""
        return self._jacobian(self.check_q(q))

    def _jacobian(self, q: np.ndarray) -> np.ndarray:
        pin.computeJointJacobians(self.model, self.data, q)
        pin.updateFramePlacements(self.model, self.data)
        return self._A_tool_link @ pin.getFrameJacobian(self.model, self.data, self.fid, pin.LOCAL)

    def manipulability(self, q) -> float:
        """Yoshikawa's manipulability sqrt(det(J Jᵀ)) of the clamp frame at ``q`` (units m³/rad⁶-mixed).

        Zero at a singularity (e.g. the wrist singularity J5 = 0, where J4 and J6 align). Source:
        T. Yoshikawa, "Manipulability of robotic mechanisms", IJRR 4(2), 1985.
        """
        J = self.jacobian(q)
        return float(math.sqrt(max(0.0, np.linalg.det(J @ J.T))))

    def _jacobian_placement(self, q: np.ndarray) -> np.ndarray:
        """The link frame's Jacobian (6, 6) (``pin.LOCAL``) at ``q``, with ``data.oMf`` of the clamp
        updated."""
        pin.computeJointJacobians(self.model, self.data, q)
        pin.updateFramePlacement(self.model, self.data, self.fid)
        return pin.getFrameJacobian(self.model, self.data, self.fid, pin.LOCAL)

    def fk_manipulability(self, q) -> tuple[np.ndarray, float]:
        """:meth:`fk` and :meth:`manipulability` of joints ``q`` (6,) rad from one kinematics pass:
        (T_display_clamp (4, 4) m, Yoshikawa's manipulability). Raises ``ValueError`` naming ``q`` if bad."""
        q = self.check_q(q)
        J = self._jacobian_placement(q)
        T = self.T_display_base @ self.data.oMf[self.fid].homogeneous @ self.T_link_tool
        return T, abs(float(np.linalg.det(J)))     # = sqrt(det(J Jᵀ)) for a square J (the tool offset: det 1)

    # ------------------------------------------------------------------ inverse kinematics
    def ik(self, T_target, q_seed, *, tol_pos: float = 1e-9, tol_rot: float = 1e-9, max_iter: int = 60,
           max_step: float = 0.25, lambda_max: float = 0.05, w_singular: float = 2e-4,
           max_jump: float = 1.0) -> IKResult:
        """Solve joints putting the clamp at ``T_target`` (4, 4, display frame, m), seeded at ``q_seed`` (6,)
        rad.

        Damped least squares with adaptive damping (see module doc); each step is capped to ``max_step``
        rad (inf-norm) and projected onto [q_lower, q_upper]. Converged when the position error is
        ≤ ``tol_pos`` m and the rotation error ≤ ``tol_rot`` rad. Damping is ``lambda_max²(1 − (w/w0)²)`` when
        the manipulability ``w`` of the current iterate is below ``w0 = 10·w_singular``.

        Statuses: "unreachable" (no convergence, no joint on a limit), "limit:J<k>" (no convergence and joint
        k sits on a limit, or the seed itself is outside the limits), "singular" (converged with
        manipulability < ``w_singular``), "jump" (converged but some joint moved more than ``max_jump`` rad
        from the seed: another branch, refused). Raises ``ValueError`` on a malformed pose or seed.
        """
        T = check_pose("T_target", T_target)
        q = self.check_q(q_seed).copy()
        outside = np.flatnonzero((q < self.q_lower - 1e-9) | (q > self.q_upper + 1e-9))
        if outside.size:
            k = int(outside[0])
            return IKResult(q, False, f"limit:{JOINT_NAMES[k]}", math.inf, math.inf, 0, 0.0)
        T_base_link = self.T_base_display @ T @ self.T_link_tool.T   # T_link_tool is its own inverse here
        M_goal = pin.SE3(T_base_link[:3, :3].copy(), T_base_link[:3, 3].copy())
        model, data, fid = self.model, self.data, self.fid
        w0 = 10.0 * w_singular
        it = 0
        w = 0.0
        J = None
        for it in range(1, max_iter + 1):  # noqa: B007
            pin.framesForwardKinematics(model, data, q)
            err = pin.log6(data.oMf[fid].actInv(M_goal)).vector
            if vnorm(err[:3]) <= tol_pos and vnorm(err[3:]) <= tol_rot:
                break
            J = pin.computeFrameJacobian(model, data, q, fid, pin.LOCAL)
            if it == 1 or w < 2.0 * w0:               # re-evaluate damping only near singular poses
                w = abs(float(np.linalg.det(J)))      # = sqrt(det(J Jᵀ)) for a square J
            if w < w0:
                lam2 = lambda_max ** 2 * (1.0 - (w / w0) ** 2)
                dq = J.T @ np.linalg.solve(J @ J.T + lam2 * np.eye(6), err)
            else:
                try:
                    dq = np.linalg.solve(J, err)
                except np.linalg.LinAlgError:   # an iterate landed exactly singular: damp this step fully
                    w = 0.0
                    dq = J.T @ np.linalg.solve(J @ J.T + lambda_max ** 2 * np.eye(6), err)
            m = float(np.max(np.abs(dq)))
            if m > max_step:
                dq *= max_step / m
            q = np.clip(q + dq, self.q_lower, self.q_upper)
        else:
            pin.framesForwardKinematics(model, data, q)
            err = pin.log6(data.oMf[fid].actInv(M_goal)).vector
        pos_err = vnorm(err[:3])
        rot_err = vnorm(err[3:])
        J = pin.computeFrameJacobian(model, data, q, fid, pin.LOCAL)
        w = abs(float(np.linalg.det(J)))              # manipulability at the returned q
        converged = pos_err <= max(tol_pos, 1e-7) and rot_err <= max(tol_rot, 1e-7)
        if not converged:
            on_limit = np.flatnonzero((q <= self.q_lower + 1e-6) | (q >= self.q_upper - 1e-6))
            status = f"limit:{JOINT_NAMES[int(on_limit[0])]}" if on_limit.size else "unreachable"
            return IKResult(q, False, status, pos_err, rot_err, it, w)
        if w < w_singular:
            return IKResult(q, False, "singular", pos_err, rot_err, it, w)
        if float(np.max(np.abs(q - q_seed))) > max_jump:
            return IKResult(q, False, "jump", pos_err, rot_err, it, w)
        return IKResult(q, True, "ok", pos_err, rot_err, it, w)

    def track(self, T_target: np.ndarray, q: np.ndarray, twist: np.ndarray) -> tuple[np.ndarray, np.ndarray,
                                                                                     float, float]:
        """One Newton step of IK from joints ``q`` (6,) rad toward the clamp pose ``T_target`` (4, 4, display
        frame, m), and the joint velocity (6,) rad/s that moves the clamp at ``twist`` (6,) (v m/s, ω rad/s,
        clamp frame) there: ``q_next = q + J⁻¹·e`` and ``q̇ = J⁻¹·twist``, both with the Jacobian ``J`` at
        ``q``. Returns (q_next, q̇, |e| (the pose error before the step: position m + rotation rad),
        manipulability at ``q``). No checks (limits, singularity, a converged error): the caller that follows
        a smooth path cycle by cycle judges them and falls back to :meth:`ik`. A step from a point a cycle
        behind ends within the square of that error (a 2 mm step at 0.3 m/s: some µm), and the next cycle's
        step corrects it. Raises ``numpy.linalg.LinAlgError`` at an exact singularity."""
        T_base_link = self.T_base_display @ T_target @ self.T_link_tool
        M_goal = pin.SE3(T_base_link[:3, :3], T_base_link[:3, 3])
        J = self._jacobian_placement(q)
        err = pin.log6(self.data.oMf[self.fid].actInv(M_goal)).vector
        rhs = np.empty((6, 2))
        rhs[:, 0] = err
        rhs[:, 1] = self._A_link_tool @ twist
        sol = np.linalg.solve(J, rhs)
        return q + sol[:, 0], sol[:, 1], float(np.abs(err).max()), abs(float(np.linalg.det(J)))

    def step_rates(self, T_target: np.ndarray, q: np.ndarray, twist: np.ndarray,
                   rates: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The joints one Newton step from ``q`` (6,) rad toward the clamp pose ``T_target`` (4, 4, display
        frame, m) moving at ``twist`` (6,) (the step of :meth:`track`), and the joint rates (6, k) that give
        the clamp-frame rates ``rates`` (6, k) (e.g. a twist and its rate: rad/s, rad/s²) through the
        Jacobian (:meth:`jacobian`) at those joints. No checks (the planner's sampled path). Raises
        ``numpy.linalg.LinAlgError`` at an exact singularity."""
        T_base_link = self.T_base_display @ T_target @ self.T_link_tool
        M_goal = pin.SE3(T_base_link[:3, :3], T_base_link[:3, 3])
        J = self._jacobian_placement(q)
        rhs = np.empty((6, 2))
        rhs[:, 0] = pin.log6(self.data.oMf[self.fid].actInv(M_goal)).vector
        rhs[:, 1] = self._A_link_tool @ twist
        qn = q + np.linalg.solve(J, rhs)[:, 0]
        return qn, np.linalg.solve(self._jacobian(qn), rates)


def clamp_joints(kin: dict, T_left: np.ndarray, T_right: np.ndarray) -> dict[str, np.ndarray]:
    """The joints (side → (6,) rad) that put each clamp at its pose (4, 4, display frame), by ``kin[side]``
    (:class:`ArmKinematics`) IK seeded at :func:`home_joints` (up to 4 tries, each from the last). Raises
    ``ValueError`` naming the arm that cannot reach its pose."""
    out = {}
    for side, T in (("left", T_left), ("right", T_right)):
        q = home_joints(side)
        for _ in range(4):
            r = kin[side].ik(T, q, max_jump=3.0)
            q = r.q
            if r.ok:
                break
        if not r.ok:
            raise ValueError(f"commanded sheet pose not reachable by the {side} arm ({r.status})")
        out[side] = q
    return out


def outside_limits(q, lower, upper) -> list[str]:
    """One line per joint of ``q`` (6,) rad outside [``lower``, ``upper``] (6,) rad (1e-9 rad of slack), e.g.
    ``"J3 60.7 deg outside [61.1, 153.9]"``; empty when all are inside."""
    return [f"J{i + 1} {math.degrees(v):.1f} deg outside [{math.degrees(lo):.1f}, {math.degrees(hi):.1f}]"
            for i,
            (v, lo, hi) in enumerate(zip(q, lower, upper, strict=True)) if not lo - 1e-9 <= v <= hi + 1e-9]
