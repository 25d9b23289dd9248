"""Encountered placement, active touch by rolling without slip, 2-D stroking and pushing (pure).

Paper §V-A and Fig. 7, generalised:

* **Away** (fingertip farther than ``touch_distance`` from the surface): the contact point A is the centre-ray
  hit (:meth:`flexsheet.model.shape_base.Shape.project`; closest point for non-convex meshes) and the sheet is
  commanded to the tangent plane at A, so the finger meets it there. The sheet's in-plane axis ``axis_u`` is
  the reference direction (``u_ref``, +y: the clamp line at home) projected onto the tangent plane, turned
  by the ψ the arms' IK chooses (:class:`~flexsheet.planning.pose_choice.PoseChoice`). A rolled offset left
  from a previous touch decays with time constant ``recentre_time``. With the application's target mark
  (:meth:`SurfacePlanner.set_mark`) the sheet waits at the landing it predicts, a few mm outside
  (:class:`~flexsheet.planning.landing.Landing`).
* **Touching** (within ``touch_distance``, released beyond ``release_distance``: hysteresis): the sheet
  rolls on the object without slip. Each update the contact moves on the surface from B₋ to B; the sheet
  rotates by the smallest rotation taking the old normal to the new one (rolling without spin, i.e.
  parallel transport of ``axis_u``) and the material point under the finger advances on the sheet by the
  geodesic step B₋→B (:meth:`Shape.geodesic_step`, exact on the cylinder's side and on spheres). So the
  arc AB equals the sheet length A′B (Fig. 7(b)) in any direction: around the cylinder, along it, over the
  other shapes. The sheet centre is ``origin = B − s_u·u − s_v·v`` where (s_u, s_v) are the contact's
  coordinates on the sheet.
* **Pushing**: a fingertip inside the object (negative distance) is projected onto the surface by the same
  rule; the sheet keeps the tangent pose there and the finger depresses it, so stroking and pushing combine.
* **Compliance**: with the object's force–depth table (:meth:`SurfacePlanner.set_force_depth`) the request
  is the table's at the contact and depth, mapped by ``stiffness_scale`` and ``contrast_gain``, matched in
  force. Without one, the stretch gives the object's stiffness (the FEM's dF/dd passed in, else the scene's
  compliance model, :mod:`flexsheet.planning.compliance`, else the configured value; × ``stiffness_scale``)
  at the contact and depth (:func:`~flexsheet.model.tension.stretch_for_stiffness`), and from
  :data:`FORCE_DEPTH` deep with the object's press given, its force
  (:func:`~flexsheet.model.tension.stretch_for_force`: a sheet stiffens with depth differently from the
  object). The stretch is clamped to what the arms can apply (status says so).
* **Limits and safety**: :func:`flexsheet.planning.pose_screen.limit_and_reach`: the rate limits, the head
  guard (sheet and arms), the reach shells and both arms' IK (the nearest reachable pose, ``reach:nearest``).
* **Tremor**: touching, the contact and normal come from the fingertip through :class:`~flexsheet.planning.
  pose_filter.PoseFilter` (``pose_cutoff``); the depth (touch, stretch) is the raw sample's along that normal.

Defined behaviour where methods fail (each has a test in ``tests/unit/planning/test_surface_planner.py``):

==============================  =========================================================================
fingertip on the skeleton       (cylinder axis, sphere centre): the last normal is held → ``hold:singular``
fingertip inside the object     pushing: projection as above; ``touching`` with negative ``depth``
past end caps / box edges       centre ray wraps over rim/edge; normals continuous (sharp box: the jump
                                is ramped by the limiter → ``rate_limited``)
sudden jump > ``jump_distance``  treated as marker re-acquisition: touch state reset → ``reacquired``,
                                motion ramped by the limiter
NaN / invalid / stale input     nothing moves: the last safe plan is returned with ``hold:<reason>``
stamp from the future           (``update(..., now=)``) a sample stamped more than
                                ``future_stamp_tolerance`` ahead of ``now`` → ``hold:future_stamp``, state
                                untouched, so it cannot make later samples look stale
clock stepped backwards         (``now`` behind the newest accepted stamp) an older sample is not stale:
                                the time base restarts at it with the last step as ``dt`` (counted
                                ``clock_rebase``); never a freeze
unreachable clamp target        arms hold the last reachable pose; status ``unreachable`` (never clipped)
contact near the sheet edge     the finger slips: offset clamped to the sheet → ``slip:sheet_edge``
object stiffer than sheet       stretch at its limit → ``object_stiffer_than_sheet``
==============================  =========================================================================

Units m, rad, s, N/m; all vectors in the display frame; vectors are float tuples for speed.
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import NamedTuple

from flexsheet.model.shape_base import Shape
from flexsheet.model.sheet import clamp_half_span, clamp_points
from flexsheet.model.tension import (
    SheetMaterial,
    TensionResult,
    max_stretch_within_force,
    stiffness,
    stretch_for_force,
    stretch_for_stiffness,
    tension,
)
from flexsheet.model.vec import (
    Vec,
    axpy,
    cross,
    dot,
    min_rotation,
    norm,
    perp_unit,
    rodrigues,
    rot_from_cols,
    sub,
)
from flexsheet.planning.landing import Landing
from flexsheet.planning.limits import RateLimiter
from flexsheet.planning.plan import Hold, Plan
from flexsheet.planning.planner_config import PlannerConfig
from flexsheet.planning.pose_choice import PoseChoice
from flexsheet.planning.pose_filter import PoseFilter
from flexsheet.planning.pose_screen import limit_and_reach

__all__ = ["FORCE_DEPTH", "TABLE_MIN_DEPTH", "SurfacePlanner"]

#: the table's force is matched no shallower than this (m): at 0 the contact law's force is 0
TABLE_MIN_DEPTH = 0.0005
#: from this push depth (m) on, a given object press is matched in force (module doc); shallower, in stiffness
FORCE_DEPTH = 0.002


class _Sample(NamedTuple):
    """A fingertip sample that passed the checks: time s, position (3,) m, stiffness N/m (None: from the
    compliance model at the contact), step s (None first)."""

    t: float
    p: Vec
    k_obj: float | None
    dt: float | None
    k_src: str = "given"


class SurfacePlanner:
    """Stateful surface planner: feed fingertip samples to :meth:`update`, get :class:`Plan` s.

    ``shape``: a :class:`flexsheet.model.shape_base.Shape`; ``config``: :class:`PlannerConfig`;
    ``compliance``: optional callable (contact (3,) m, normal (3,), depth m) → the object's stiffness N/m
    there (e.g. :class:`flexsheet.planning.compliance.SceneCompliance`), used when :meth:`update` gets no
    stiffness (else ``config.object_stiffness``). The first valid sample initialises the pose (no ramp).
    ``last`` is the last safe plan (``None`` before the first); :meth:`hold` republishes it with a reason (a
    lost marker, a refused input). ``counts`` counts statuses.
    """

    def __init__(self, shape: Shape, config: PlannerConfig | None = None, compliance=None, guard=None,
                 arm_reach=None):
        self.shape = shape
        self.guard = guard          # a flexsheet.planning.head_guard.HeadGuard, or None (no head tracking)
        self.arm_reach = arm_reach  # a flexsheet.planning.arm_reach.ArmReach, or None (the reach shells only)
        self.cfg = config or PlannerConfig()
        self.compliance = compliance
        self.limiter = RateLimiter(self.cfg.limits)
        self.pose_filter = PoseFilter(self.cfg.pose_cutoff, self.cfg.pose_velocity_cutoff)
        self.landing = Landing(shape, self.cfg)     # the application's target mark, :meth:`set_mark`
        #: ψ between touches (:class:`~flexsheet.planning.pose_choice.PoseChoice`); None: the paper's rule
        self.pose_choice = (PoseChoice(shape, self.cfg, arm_reach, guard)
                            if arm_reach is not None and self.cfg.psi_range > 0.0 else None)
        self._eps_max = max_stretch_within_force(self.cfg.material)
        #: the arms' pull limit at their pose, N (None: only the
        #: material's ``max_force``), :meth:`set_pull_limit`
        self.pull_limit: float | None = None
        #: the object's force–depth table (:meth:`set_force_depth`); None: the stiffness given or modelled
        self.force_depth = None
        self.reset()

    @property
    def max_stretch(self) -> float:
        """The largest stretch the planner asks for now: ``max_stretch`` and ``max_force``, capped by the pull
        limit (:meth:`set_pull_limit`)."""
        return self._eps_max

    def set_force_depth(self, table) -> None:
        """What the object asks, from its own FEM (:class:`flexsheet.model.force_depth.ForceDepth`; None: back
        to the stiffness given to :meth:`update` or the compliance model). With a table the request at contact
        q, depth d is ``table.mapped(q, max(d, TABLE_MIN_DEPTH), stiffness_scale, contrast_gain)``, matched in
        force at that depth (the sheet's force–depth and the object's differ in shape, so matching the slope
        at a shallow depth misses the force deeper); ``object_stiffness`` and ``object_press`` passed to
        :meth:`update` are then not used (source "table")."""
        self.force_depth = table
        self._tcache = None

    def set_mark(self, t: float, point, normal, visible: bool = True) -> None:
        """The target mark the application shows at ``t`` s: ``point`` (3,) m, outward ``normal`` (3,); while
        the finger is away the sheet waits there (:class:`~flexsheet.planning.landing.Landing`); ``visible``
        False: none. Raises ``ValueError`` for a malformed mark."""
        self.landing.set_mark(t, point, normal, visible)

    def set_pull_limit(self, pull: float | None) -> None:
        """Cap the clamp force at ``pull`` N (the arms' torque limit at their pose,
        :func:`flexsheet.arm.pull_limit.max_pull`) below the material's ``max_force``; None lifts the cap. A
        stretch asked beyond it is clamped and reported ``object_stiffer_than_sheet``. Raises ``ValueError``
        for a negative or NaN pull."""
        if pull is not None and not (pull >= 0.0):
            raise ValueError(f"pull limit must be >= 0 N or None, got {pull!r}")
        if pull == self.pull_limit:
            return
        self.pull_limit = pull
        mat = self.cfg.material
        if pull is not None and pull < mat.max_force:
            mat = replace(mat, max_force=max(float(pull), 1e-6))
        self._eps_max = max(max_stretch_within_force(mat), mat.min_stretch)
        self._tcache = None

    def reset(self) -> None:
        """Forget all state (as at start)."""
        self.last: Plan | None = None
        self.t_last: float | None = None
        self.dt_last: float | None = None
        self.p_last: Vec | None = None
        self.q_last: Vec | None = None
        self.n_last: Vec | None = None
        self.u_last: Vec | None = None
        self.s: tuple[float, float] = (0.0, 0.0)
        self.touching = False
        self.limiter.clear()
        self.pose_filter.reset()
        if self.pose_choice is not None:
            self.pose_choice.reset()
        self._tcache: tuple[float, float, float, float, TensionResult] | None = None
        self._k_model: float | None = None
        self.counts: dict[str, int] = {}

    # ---------------------------------------------------------------------------------------------
    def hold(self, reason: str, t: float | None = None) -> Plan | None:
        """The last safe plan again with status ``reason`` (and time ``t`` s if given), counted in ``counts``;
        ``None`` before the first plan. Used for a lost marker and for every refused input."""
        self.counts[reason] = self.counts.get(reason, 0) + 1
        if self.last is None:
            return None
        return replace(self.last, t=self.last.t if t is None else t, status=reason)

    def _tension(self, k: float, off_u: float, off_v: float, depth: float) -> TensionResult:
        c = self._tcache
        if (c is not None and abs(c[0] - k) <= 1e-6 * max(1.0, k) and abs(c[1] - off_u) <= 1e-4
                and abs(c[2] - off_v) <= 1e-4 and abs(c[3] - depth) <= 1e-4):
            return c[4]
        r = stretch_for_stiffness(k, self.cfg.material, off_u, self._eps_max, depth, off_v)
        self._tcache = (k, off_u, off_v, depth, r)
        return r

    def update(self, t: float, p, object_stiffness: float | None = None, now: float | None = None,
               object_press: tuple[float, float] | None = None) -> Plan | None:
        """Plan from a fingertip sample ``p`` (3,) m at time ``t`` s; ``object_stiffness`` N/m (e.g. the FEM's
        dF/dd) overrides the compliance model and the configured value; either is multiplied by
        ``stiffness_scale``. ``object_press`` (force N, depth m): the object's force at a depth (the FEM's
        last solve), matched in force from :data:`FORCE_DEPTH` on (module doc); ignored when malformed.
        ``now`` s: the caller's clock (the node's ``now()``, same time base as ``t``), which judges stamps
        from the future and backward clock steps (see the module table); None: ``t`` alone. Returns the new
        :class:`Plan`, or a held copy of the last safe plan with status ``hold:<reason>`` for invalid input
        (``None`` if there is none yet). Never raises for bad samples: the reason is counted in ``counts``.

        Steps: check the sample → re-acquisition → project onto the shape (§V-A) → touch hysteresis → roll
        or recentre (Fig. 7(b)) → stretch for the stiffness → keep the contact on the sheet → rate limits
        and reach → the plan."""
        s = self._sample(t, p, object_stiffness, now)
        if not isinstance(s, _Sample):
            return self.hold(*s)
        cfg = self.cfg
        status: list[str] = []
        # re-acquisition: a jump no finger can make between two samples
        if self.p_last is not None and norm(sub(s.p, self.p_last)) > cfg.jump_distance:
            self.touching = False
            status.append("reacquired")
        pf = self.pose_filter.step(s.p, None if status else s.dt)   # the pose path's fingertip, touching;
        pf = pf if self.touching else s.p                           # away the raw one: the sheet waits there
        proj = self.shape.project(pf, self.n_last, cfg.singular_eps)
        if proj.singular:
            status.append(Hold.SINGULAR)
        q, n, dist = proj.point, proj.normal, proj.distance + dot(proj.normal, sub(s.p, pf))
        depth = max(0.0, -dist)
        k_obj, k_source, table_force = self._request(s, q, n, dist)
        if k_obj is None:
            return self.hold(Hold.INVALID_STIFFNESS, s.t)
        was_touching = self.touching
        self._touch(dist)
        self.landing.cfg = cfg                  # until it lands: where the application's mark says it will
        last = None if self.last is None else (self.last.contact, self.last.normal)
        q, n, lift = self.landing.place(s.t, s.dt, dist, q, n, last, self.touching)
        su, sv, u = self._roll(q, n, s.dt, was_touching)
        if self.pose_choice is not None and not (self.touching and was_touching):   # ψ: not while rolling
            st0 = self.last.stretch if self.last is not None else cfg.material.min_stretch
            u = self.pose_choice.axis(s.t, q, n, (su, sv), st0, not self.touching) or u
        v = cross(n, u)
        tr = self._stretch(k_obj, table_force, su, sv, depth, object_press)
        if tr.saturated:
            status.append(tr.saturated)
        su, sv = self._keep_on_sheet(su, sv, tr.stretch, status)
        origin = axpy(lift, n, axpy(-sv, v, axpy(-su, u, q)))
        o, (nc, uc, vc), st, left, right, margin = limit_and_reach(self, origin, rot_from_cols(n, u, v),
                                                                   tr.stretch, s.dt, status, (su, sv))
        mat = cfg.material
        plan = Plan(s.t, q, nc, uc, vc, o, (su, sv), st, tr.tension if st == tr.stretch else tension(st, mat),
                    tr.stiffness if st == tr.stretch else _stiffness_or_zero(st, mat, su, sv, depth), k_obj,
                    depth, self.touching, ";".join(status) if status else "ok", left, right, margin,
                    mat.size, k_source)
        for s_ in status:
            self.counts[s_] = self.counts.get(s_, 0) + 1
        self.t_last, self.p_last, self.q_last, self.n_last, self.u_last, self.s = s.t, s.p, q, n, u, (su, sv)
        if s.dt is not None:
            self.dt_last = s.dt
        if "unreachable" not in status or self.last is None:
            self.last = plan
        return plan

    def hold_pose(self, reason: str, t: float, p, object_stiffness: float | None = None,
                  now: float | None = None,
                  object_press: tuple[float, float] | None = None) -> Plan | None:
        """The last plan's pose held, with status ``reason`` (a lost head), while the stretch still follows
        the push: fingertip sample ``p`` (3,) m at ``t`` s is planned as :meth:`update` plans it (the request
        at its contact and depth, at the held contact's offset on the sheet), and the stretch moves toward
        that at no more than :meth:`hold_stretch_rate`, the sheet at rest. A refused sample, an unreachable
        stretch or no plan yet: :meth:`hold` (``None`` before the first plan). Never raises for bad
        samples."""
        s = self._sample(t, p, object_stiffness, now)
        L = self.last
        if L is None or not isinstance(s, _Sample):
            return self.hold(reason)
        self.pose_filter.step(s.p, s.dt)
        proj = self.shape.project(s.p, L.normal, self.cfg.singular_eps)
        depth = max(0.0, -proj.distance)
        k_obj, k_source, table_force = self._request(s, proj.point, proj.normal, proj.distance)
        if k_obj is None:
            return self.hold(reason, s.t)
        self.counts[reason] = self.counts.get(reason, 0) + 1
        cfg, mat, (su, sv) = self.cfg, self.cfg.material, L.offset
        tr = self._stretch(k_obj, table_force, su, sv, depth, object_press)
        dt = s.dt if s.dt is not None else cfg.max_dt
        mx = self.hold_stretch_rate() * dt
        st = L.stretch + max(-mx, min(mx, tr.stretch - L.stretch))
        left, right = clamp_points(L.origin, L.axis_u, st, mat.size)
        ok, margin = cfg.reach.reachable(left, right)
        self.t_last, self.p_last = s.t, s.p
        if s.dt is not None:
            self.dt_last = s.dt
        self._touch(proj.distance)
        if not ok:
            return replace(L, t=s.t, status=f"{reason};unreachable", reach_margin=margin)
        self.limiter.reset(L.origin, rot_from_cols(L.normal, L.axis_u, L.axis_v), st)
        self.last = replace(L, t=s.t, stretch=st, tension=tension(st, mat),
                            stiffness=_stiffness_or_zero(st, mat, su, sv, depth), object_stiffness=k_obj,
                            depth=depth,
                            touching=self.touching,
                            status=f"{reason};{tr.saturated}" if tr.saturated else reason,
                            left=left, right=right, reach_margin=margin,
                            k_source=k_source)
        return self.last

    def hold_stretch_rate(self) -> float:
        """1/s: how fast :meth:`hold_pose` changes the stretch: the limits' ``stretch_rate``, and no faster
        than moves each clamp (half the sheet's span from the centre) at the head guard's reduced speed (0.25
        m/s without a guard), the one motion of a held sheet near a head it cannot see."""
        vs = self.guard.keepout.reduced_speed if self.guard is not None else 0.25
        return min(self.cfg.limits.stretch_rate, vs / (0.5 * self.cfg.material.size))

    # -- the steps of update ----------------------------------------------------------------------
    def _touch(self, dist: float) -> None:
        """Touch hysteresis on the signed distance ``dist`` m: touching from ``touch_distance``, released
        beyond ``release_distance``."""
        if not self.touching and dist <= self.cfg.touch_distance:
            self.touching = True
        elif self.touching and dist > self.cfg.release_distance:
            self.touching = False

    def _request(self, s: _Sample, q: Vec, n: Vec, dist: float) -> tuple[float | None, str, float]:
        """What the object asks at contact ``q``, normal ``n``, signed distance ``dist`` m: (stiffness N/m or
        None when none can be had, its source, the table's force N or 0 without a table)."""
        if self.force_depth is None:
            k_obj, k_source = self._object_stiffness(s, q, n, dist)
            return k_obj, k_source, 0.0
        cfg = self.cfg
        try:
            f, k_obj = self.force_depth.mapped(q, max(-dist, TABLE_MIN_DEPTH), cfg.stiffness_scale,
                                               cfg.contrast_gain)
        except ValueError:
            return None, "table", 0.0
        return k_obj, "table", f

    def _stretch(self, k_obj: float, table_force: float, su: float, sv: float, depth: float,
                 object_press) -> TensionResult:
        """Stiffness (or force) → stretch at the contact (``su``, ``sv``) m from the sheet's centre and
        ``depth`` m."""
        mat = self.cfg.material
        if self.force_depth is not None:  # the table's force, matched at every depth (≥ TABLE_MIN_DEPTH)
            return stretch_for_force(table_force, mat, su, max(depth, TABLE_MIN_DEPTH), self._eps_max, sv)
        force = self._object_force(object_press, k_obj, depth)
        return (self._tension(k_obj, su, sv, depth) if force is None
                else stretch_for_force(force, mat, su, depth, self._eps_max, sv))

    def _sample(self, t, p, object_stiffness, now=None) -> _Sample | tuple[str, float | None]:
        """The checked sample, or (hold reason, hold time) for an input the planner refuses."""
        try:
            t = float(t)
            p = (float(p[0]), float(p[1]), float(p[2])) if len(p) == 3 else None
        except (TypeError, ValueError, IndexError):
            p = None
        if p is None or not (math.isfinite(p[0]) and math.isfinite(p[1]) and math.isfinite(p[2])):
            return Hold.INVALID_FINGERTIP, None
        if not math.isfinite(t):
            return Hold.INVALID_STAMP, None
        if now is not None and math.isfinite(now) and t > now + self.cfg.future_stamp_tolerance:
            return Hold.FUTURE_STAMP, None
        k_obj, src = object_stiffness, "given"
        if k_obj is None and self.compliance is None:
            k_obj, src = self.cfg.object_stiffness, "param"
        if k_obj is not None and not (math.isfinite(k_obj) and k_obj >= 0.0):
            return Hold.INVALID_STIFFNESS, t
        if self.t_last is None:
            return _Sample(t, p, k_obj, None, src)
        dt = t - self.t_last
        if dt <= 0.0:
            if now is None or not self.t_last > now:
                return Hold.STALE_FINGERTIP, None
            # the newest accepted stamp is ahead of the clock: the clock stepped back (or that stamp ran ahead
            # within the tolerance). It must not gate later samples: restart the time base here.
            self.counts["clock_rebase"] = self.counts.get("clock_rebase", 0) + 1
            dt = self.dt_last if self.dt_last is not None else self.cfg.max_dt
        return _Sample(t, p, k_obj, min(dt, self.cfg.max_dt), src)

    def _object_force(self, press, k_obj: float, depth: float) -> float | None:
        """The object's force (N, × ``stiffness_scale``) at ``depth``: the press (force, depth) extrapolated
        by ``k_obj`` (already scaled); None below :data:`FORCE_DEPTH`, without a press or for a malformed
        one."""
        if press is None or depth < FORCE_DEPTH:
            return None
        try:
            f, d = float(press[0]), float(press[1])
        except (TypeError, ValueError, IndexError):
            return None
        if not (math.isfinite(f) and math.isfinite(d) and f >= 0.0 and d >= 0.0):
            return None
        return max(0.0, f * self.cfg.stiffness_scale + k_obj * (depth - d))

    def _object_stiffness(self, s: _Sample, q: Vec, n: Vec, dist: float) -> tuple[float | None, str]:
        """(stiffness N/m × ``stiffness_scale``, source) for the sample: the one given (or the config's), else
        the compliance model at contact ``q``, normal ``n``, depth max(0, −``dist``), low-passed with
        ``stiffness_tau``; ``None`` when the model fails or gives a negative / non-finite value."""
        scale_k = self.cfg.stiffness_scale
        if s.k_obj is not None:
            return s.k_obj * scale_k, s.k_src
        try:
            k = float(self.compliance(q, n, max(0.0, -dist)))
        except (ValueError, ArithmeticError):
            return None, "scene"
        if not (math.isfinite(k) and k >= 0.0):
            return None, "scene"
        tau = self.cfg.stiffness_tau
        if self._k_model is not None and s.dt is not None and tau > 0.0:
            k = self._k_model + (1.0 - math.exp(-s.dt / tau)) * (k - self._k_model)
        self._k_model = k
        return k * scale_k, "scene"

    def _roll(self, q: Vec, n: Vec, dt: float | None, was_touching: bool) -> tuple[float, float, Vec]:
        """Contact coordinates (s_u, s_v) m on the sheet and the new ``axis_u`` for contact ``q``, normal
        ``n``.

        Touching: rolling without slip — parallel-transport u, advance the material point by the geodesic
        step. Not touching: the offset decays with ``recentre_time`` and u is ``u_ref`` in the tangent
        plane."""
        cfg = self.cfg
        su, sv = self.s
        if self.touching and was_touching and self.n_last is not None and self.q_last is not None \
                and self.u_last is not None:
            u0 = self.u_last
            v0 = cross(self.n_last, u0)
            g = self.shape.geodesic_step(self.q_last, q)
            su += dot(g, u0)
            sv += dot(g, v0)
            mr = min_rotation(self.n_last, n)
            u = rodrigues(mr[0], mr[1], u0) if mr is not None else u0
            return su, sv, perp_unit(n, u)
        if dt is not None and (su != 0.0 or sv != 0.0):
            f = math.exp(-dt / cfg.recentre_time)
            su, sv = su * f, sv * f
        ref = (cfg.u_ref if abs(dot(cfg.u_ref, n)) < 0.999 * norm(cfg.u_ref) or self.u_last is None
               else self.u_last)
        return su, sv, perp_unit(n, ref)

    def _keep_on_sheet(self, su: float, sv: float, stretch: float, status: list[str]) -> tuple[float, float]:
        """The finger must stay on the sheet (``sheet_margin`` from its edges): otherwise it slips — the
        offset is clamped and ``slip:sheet_edge`` appended to ``status``."""
        cfg = self.cfg
        hu = clamp_half_span(stretch, cfg.material.size) - cfg.sheet_margin
        hv = 0.5 * cfg.material.size - cfg.sheet_margin             # free edges: half the unstretched width
        if abs(su) > hu or abs(sv) > hv:
            status.append("slip:sheet_edge")
            return max(-hu, min(hu, su)), max(-hv, min(hv, sv))
        return su, sv


def _stiffness_or_zero(stretch: float, mat: SheetMaterial, su: float, sv: float, depth: float) -> float:
    """Stiffness presented at a rate-limited stretch and ``depth`` m (N/m); 0 when the contact is not between
    the clamps."""
    try:
        return stiffness(stretch, mat, su, depth, sv)
    except ValueError:
        return 0.0
