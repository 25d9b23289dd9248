"""The geometrically nonlinear reference pushed along a path (pure): load stepping in the push depth with
Newton (:mod:`flexsheet.fem.reference.newton`) at each step (:func:`solve_path`, :func:`solve_path_capsule`,
one :class:`PathState` per requested depth), and the unloading sweep that finds the stable branch of a
bistable push (:func:`unload_sweep`, :func:`stable_states`).

Units SI: m, N, Pa. Display frame (cylinder axis along +y through the mesh centre).
"""

from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING

import numpy as np

from flexsheet.fem.reference.capsule_contact import CONTACT_LAWS, DEFAULT_CONTACT, Capsule, capsule_at
from flexsheet.fem.reference.newton import newton_resumed

log = logging.getLogger(__name__)

if TYPE_CHECKING:
    from flexsheet.fem.reference.hyperelastic import HyperelasticModel

__all__ = ["PathState", "solve_path", "solve_path_capsule", "stable_states", "unload_sweep",
           "BRANCH_MEET_TOL"]


@dataclass
class PathState:
    """Converged state at one depth: ``depth`` m, ``u`` (P, 3) m displacement of every DOF point,
    ``force`` N (finger force along p̂), ``force_vec`` (3,) N, ``iterations``, ``converged``, ``min_detF``
    (smallest det F over quadrature points and element nodes), ``inverted`` (elements with det F ≤ 0 at a
    quadrature point or node), ``max_strain`` (largest principal Green–Lagrange strain), ``penetration`` m
    (deepest surface point inside the finger), ``n_contact``; ``extra["anchors"]`` (sticking contact) the
    anchors (Fc, Qf, 3) m the state was solved with (:class:`Capsule`)."""

    depth: float
    u: np.ndarray
    force: float
    force_vec: np.ndarray
    iterations: int
    converged: bool
    min_detF: float
    inverted: int
    max_strain: float
    penetration: float
    n_contact: int
    seconds: float = 0.0
    extra: dict = field(default_factory=dict)


def solve_path(model: HyperelasticModel, angle: float, depths, finger_radius: float, step: float = 0.001,
               iters: int = 30, tol_u: float = 1e-6, tol_r: float | None = None,
               substeps_max: int = 3, contact: str = DEFAULT_CONTACT) -> list[PathState]:
    """Push the capsule finger radially into the cylinder at azimuth ``angle`` (rad, :func:`capsule_at` on
    ``model.mesh``'s radius and centre) through ``depths`` (m, ascending, ≥ 0); see :func:`solve_path_capsule`
    for the load stepping, the return value and the errors raised."""
    if not math.isfinite(angle):
        raise ValueError(f"angle must be finite, got {angle!r}")
    m = model
    return solve_path_capsule(model,
                              lambda d: capsule_at(angle, d, finger_radius, m.mesh.radius, m.mesh.center),
                              depths, step, iters, tol_u, tol_r, substeps_max,
                              label=f"angle {math.degrees(angle):.1f} deg", contact=contact)


def _check_path_args(depths, step: float, capsule, contact: str) -> np.ndarray:
    """``depths`` as an array, after :func:`solve_path_capsule`'s arguments are checked (``ValueError``)."""
    depths = np.asarray(depths, float)
    if depths.ndim != 1 or len(depths) == 0 or not np.all(np.isfinite(depths)) or np.any(depths < 0):
        raise ValueError(f"depths must be a non-empty 1-D array of finite values >= 0 m, got {depths!r}")
    if np.any(np.diff(depths) < 0):
        raise ValueError("depths must be ascending")
    if not (math.isfinite(step) and step > 0):
        raise ValueError(f"step must be > 0 m, got {step!r}")
    if not callable(capsule):
        raise ValueError(f"capsule must be a callable depth -> Capsule, got {type(capsule).__name__}")
    if contact not in CONTACT_LAWS:
        raise ValueError(f"contact must be one of {CONTACT_LAWS}, got {contact!r}")
    return depths


class _PathPush:
    """:func:`solve_path_capsule`'s walk along the push: the iterate ``u`` at depth ``d_cur``, the previous
    one (``u_prev`` at ``d_prev``, for the extrapolated guess), the sticking anchors, Newton's resume state
    and the current load step size."""

    def __init__(self, m: HyperelasticModel, capsule, sticking: bool, step: float, iters: int, tol_u: float,
                 tol_r: float | None, substeps_max: int, label: str):
        self.m, self.capsule, self.sticking = m, capsule, sticking
        self.iters, self.tol_u, self.substeps_max, self.label = iters, tol_u, substeps_max, label
        self.anchors = None
        self.k = m.penalty()
        self.tol_r = tol_r if tol_r is not None else 1e-6 * m.E_ref * m.h_contact ** 2 * 10
        self.u = np.zeros((len(m.points), 3))
        self.u_prev, self.d_prev = None, 0.0
        self.d_cur = 0.0
        self.nstate: dict = {}
        self.step_now = step

    def caps(self, d: float):
        """The finger at depth ``d`` (with the anchors, sticking)."""
        caps = self.capsule(d)
        if self.sticking:
            caps = replace(caps, anchors=self.anchors)
        return caps

    def load_step(self, target: float):
        """One load step toward ``target`` m, halved on a failed Newton solve (module doc of
        :func:`solve_path_capsule`): returns (Newton iterations, converged)."""
        m = self.m
        h = min(self.step_now, target - self.d_cur)
        u_last = None
        its_total = 0
        if self.sticking:                # points touching the finger at the last converged state stick to it
            self.anchors = m.stick_anchors(self.u, self.capsule(self.d_cur), self.anchors)
        for _ in range(self.substeps_max + 1):
            d_new = self.d_cur + h
            caps = self.caps(d_new)
            guess = self.u
            if self.u_prev is not None and self.d_cur > self.d_prev:
                g2 = self.u + (self.u - self.u_prev) * (h / (self.d_cur - self.d_prev))
                if math.isfinite(m.energy(g2, None, 0.0)):
                    guess = g2
            u_new, its, conv, u_try = newton_resumed(m, guess, caps, self.k, self.iters, self.tol_u,
                                                     self.tol_r,
                                                     self.nstate)
            u_last = u_try if u_try is not None else u_last
            its_total += its
            if conv:
                break
            h *= 0.5
            self.step_now = min(self.step_now, h)
        else:
            if u_last is None:
                raise RuntimeError(f"Newton failed at depth {self.d_cur * 1e3:.2f} mm -> {d_new * 1e3:.2f} "
                                   f"mm ({self.label})")
            u_new = u_last          # give up on this step: keep its last iterate, flagged not converged
            log.info(f"  Newton did not converge at {d_new * 1e3:.2f} mm ({self.label})")
        self.u_prev, self.d_prev = self.u, self.d_cur
        self.u, self.d_cur = u_new, d_new
        return its_total, conv

    def state(self, its_total: int, conv_all, t0: float) -> PathState:
        """The :class:`PathState` at the current depth."""
        st = _path_state(self.m, self.u, self.caps(self.d_cur), self.k, self.d_cur, its_total, conv_all, t0)
        if self.sticking:
            st.extra["anchors"] = self.anchors.copy()
        return st


def solve_path_capsule(model: HyperelasticModel, capsule, depths, step: float = 0.001, iters: int = 30,
                       tol_u: float = 1e-6, tol_r: float | None = None, substeps_max: int = 3,
                       label: str = "path", contact: str = DEFAULT_CONTACT) -> list[PathState]:
    """Push a rigid finger given by ``capsule(depth) -> Capsule`` (depth m; any object, any push direction)
    through ``depths`` (m, ascending, ≥ 0), load steps of at most ``step`` m; returns one :class:`PathState`
    per requested depth (``force`` along the capsule's direction, full-body force with the symmetry planes). A
    Newton call that runs out of ``iters`` iterations (not failed: e.g. a snap-through under way) is continued
    from its last iterate at the same depth, up to :data:`~flexsheet.fem.reference.newton.RESUME_MAX` more
    calls (nh-7; a step stuck for good thus costs (1 + RESUME_MAX)× the iterations before each halving). A
    load step whose Newton solve fails otherwise, or still has not converged then, is halved (up to
    ``substeps_max`` times) and the load steps after it keep the halved size (the path got hard: on the 3.4 mm
    cylinder mesh a 2.5 mm step past 47.5 mm spent 60 iterations per try before halving, nh-5); if it still
    fails, its last iterate is kept and the state is flagged ``converged=False`` (bounded time; the caller
    decides).

    ``contact`` (a modelling choice, :data:`CONTACT_LAWS`): ``"frictionless"`` — non-penetration only, the
    surface slides freely on the finger; ``"sticking"`` — a fingertip that does not slip on soft tissue
    (infinite friction): a contact quadrature point that is inside the finger at a converged load step is
    stuck to the finger point nearest to it (:meth:`HyperelasticModel.stick_anchors`) and from the next load
    step on follows the finger (penalty k/2 |x − anchor|², the same k; "inside" is gap < ε, the penalty's
    onset, :meth:`HyperelasticModel.stick_anchors`); anchors are added after every load step, never released
    (a monotone push). Raises ``ValueError`` on bad depths or an unknown ``contact`` and ``RuntimeError`` when
    a step has no valid iterate at all."""
    depths = _check_path_args(depths, step, capsule, contact)
    walk = _PathPush(model, capsule, contact == "sticking", step, iters, tol_u, tol_r, substeps_max, label)
    out = []
    for target in depths:
        t0 = time.perf_counter()
        its_total = 0
        conv_all = True
        while walk.d_cur < target - 1e-12:
            its, conv = walk.load_step(target)
            its_total += its
            conv_all &= conv
        st = walk.state(its_total, conv_all, t0)
        out.append(st)
        log.info(f"  depth {walk.d_cur * 1e3:5.1f} mm: F={st.force:.4f} N, {its_total} Newton its, "
                f"min det F={st.min_detF:.3f}, inverted={st.inverted}, pen={st.penetration * 1e3:.3f} mm, "
                f"{st.seconds:.1f} s")
    return out


def _path_state(m: HyperelasticModel, u: np.ndarray, caps: Capsule, k: float, depth: float, iterations: int,
                converged: bool, t0: float) -> PathState:
    """The :class:`PathState` of displacement ``u`` (P, 3) m under ``caps`` at ``depth`` m: the finger force
    (full body, the symmetry planes' mirror images added), the element checks; ``t0`` its start
    (perf_counter)."""
    fvec, pen, ncon = m.contact_force(u, caps, k)
    fvec = m.sym_factor * fvec * np.array([1.0, 0.0 if m.sym_y else 1.0, 0.0 if m.sym_z else 1.0])
    minJ, ninv, emax = m.checks(u)
    return PathState(float(depth), u.copy(), float(fvec @ caps.direction), fvec, int(iterations),
                     bool(converged),
                     minJ, ninv, emax, pen, ncon, time.perf_counter() - t0)


def stable_states(model: HyperelasticModel, capsule, states: list[PathState], step: float = 0.0025,
                  iters: int = 30) -> tuple[list[PathState], np.ndarray, np.ndarray]:
    """Per depth the lower-energy of the loading state (``states``, :func:`solve_path_capsule`) and the
    unloaded one (:func:`unload_sweep`): where a push is bistable, the stable branch rather than the
    metastable one the loading path may stay on (both are equilibria under the same finger; the lower total
    potential Π is the one a perturbation cannot leave). The unloaded state is taken only when it converged
    and lies farther than :data:`BRANCH_MEET_TOL` from the loading one (else they are one state). Returns
    (states, branch (D,) int: 1 where the unloaded state was taken, energies (D, 2) J: Π of the loading and of
    the unloaded state at each depth). Frictionless contact only. Costs a Newton solve per load step (on the
    3.4 mm half model at 5° and 10°, 41 min of one core each with another solve beside it, about as long as
    the loading path: the unloading steps start from the previous state with no predictor and need up to ~35
    iterations at 5–20 mm)."""
    sw = unload_sweep(model, capsule, states, step=step, iters=iters)
    out, branch = [], np.zeros(len(states), np.int64)
    energies = np.array([[un.extra["energy_loading"], un.extra["energy"]] for un in sw])
    for j, (ld, un) in enumerate(zip(states, sw, strict=True)):
        take = (un.converged and un.extra["energy"] < un.extra["energy_loading"]
                and float(np.abs(un.u - ld.u).max()) > BRANCH_MEET_TOL)
        out.append(un if take else ld)
        branch[j] = int(take)
    return out, branch, energies


#: two states of one push lie on the same branch when no DOF point is farther apart than this (m): 20× the
#: Newton tolerance on the step, far below the 0.7 mm target (:func:`stable_states`)
BRANCH_MEET_TOL = 2e-5


def unload_sweep(model: HyperelasticModel, capsule, states: list[PathState], step: float = 0.0025,
                 iters: int = 30, tol_u: float = 1e-6, tol_r: float | None = None,
                 substeps_max: int = 3) -> list[PathState]:
    """The equilibria of a frictionless push found by *unloading*: from the deepest of ``states`` (a loading
    path, :func:`solve_path_capsule`, ascending depths) the finger is withdrawn through the same depths, load
    steps of at most ``step`` m, each Newton solve started from the last unloaded state (halved on failure as
    in :func:`solve_path_capsule`). A push into a soft body can be bistable: the loading path stays on a
    metastable branch (a fold beside the finger not yet snapped) that unloading, starting past the snap, does
    not visit. Returns one :class:`PathState` per depth of ``states`` (ascending), with ``extra["energy"]``
    (J, Π of the unloaded state) and ``extra["energy_loading"]`` (Π of the loading state there); the deepest
    state is the loading one itself (taken as stable: the push is assumed past its snaps there; the 50 mm
    states of 5°–20° on the 3.4 mm mesh are). The sweep runs to the shallowest depth: the two branches
    coincide past the snap (at 10° on the 3.4 mm mesh from 45 mm) and part only below it, so meeting the
    loading path says nothing about the depths still to come. Frictionless contact only (a sticking finger's
    anchors depend on the loading history). Raises ``ValueError`` on an empty or unsorted ``states``,
    ``RuntimeError`` when a step has no valid iterate at all."""
    if not states:
        raise ValueError("states must be a non-empty loading path")
    if any("anchors" in s.extra for s in states):
        raise ValueError("unload_sweep needs a frictionless push: these states carry a sticking finger's "
                         "anchors")
    d = np.array([s.depth for s in states])
    if np.any(np.diff(d) <= 0):
        raise ValueError(f"states must have ascending depths, got {d.tolist()}")
    m = model
    k = m.penalty()
    tol_r = tol_r if tol_r is not None else 1e-6 * m.E_ref * m.h_contact ** 2 * 10
    out: list[PathState | None] = [None] * len(states)
    top = states[-1]
    e_top = m.energy(top.u, capsule(top.depth), k)
    out[-1] = replace(top, extra={**top.extra, "energy": e_top, "energy_loading": e_top})
    u, d_cur = top.u.copy(), top.depth
    nstate: dict = {}
    for j in range(len(states) - 2, -1, -1):
        t0 = time.perf_counter()
        target, its_total, conv_all = states[j].depth, 0, True
        h_max = step
        while d_cur > target + 1e-12:
            h = min(h_max, d_cur - target)
            u_last = None
            for _ in range(substeps_max + 1):
                d_new = d_cur - h
                u_new, its, conv, u_try = newton_resumed(m, u, capsule(d_new), k, iters, tol_u, tol_r, nstate)
                u_last = u_try if u_try is not None else u_last
                its_total += its
                if conv:
                    break
                h *= 0.5
                h_max = min(h_max, h)
            else:
                if u_last is None:
                    raise RuntimeError(f"Newton failed unloading from {d_cur * 1e3:.2f} mm to "
                                       f"{d_new * 1e3:.2f} mm")
                u_new = u_last
            conv_all &= conv
            u, d_cur = u_new, d_new
        caps = capsule(target)
        st = _path_state(m, u, caps, k, target, its_total, conv_all, t0)
        e_un, e_ld = m.energy(u, caps, k), m.energy(states[j].u, caps, k)
        st.extra.update(energy=e_un, energy_loading=e_ld)
        out[j] = st
        gap = float(np.abs(u - states[j].u).max())
        log.info(f"  unloading {target * 1e3:5.2f} mm: {its_total} Newton its, Π {e_un:.6g} J against the "
                 f"loading path's {e_ld:.6g} J, {gap * 1e3:.3f} mm apart, {st.seconds:.1f} s")
    return out
