"""The surface planner's settings (:class:`PlannerConfig`), checked on construction. Units m, s, N/m."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from flexsheet.model.checks import check_positive
from flexsheet.model.motion_limits import MotionLimits
from flexsheet.model.tension import SheetMaterial
from flexsheet.model.vec import Vec, finite, norm
from flexsheet.planning.limits import ReachModel

__all__ = ["PlannerConfig"]


@dataclass(frozen=True)
class PlannerConfig:
    """Planner settings (SI). ``touch_distance``/``release_distance`` m: touch hysteresis on the signed
    distance; ``singular_eps`` m: skeleton distance below which the centre ray is undefined;
    ``jump_distance`` m: a larger step between samples is a re-acquired marker; ``recentre_time`` s;
    ``u_ref`` (3,): preferred in-plane axis; ``sheet_margin`` m: the contact keeps this far from the sheet
    edges; ``object_stiffness`` N/m: default virtual stiffness (used when neither a stiffness is passed nor
    a compliance model is given); ``stiffness_scale``: haptic scale — the sheet is asked for this many times
    the object's stiffness (1: the object's own; < 1 maps an object stiffer than the sheet into the range the
    arms can apply, reported in every plan's ``object_stiffness``); ``contrast_gain`` γ: with the object's
    force–depth table (:meth:`SurfacePlanner.set_force_depth`) the sheet is asked for
    s·F_ref·(F/F_ref)^γ (:meth:`flexsheet.model.force_depth.ForceDepth.mapped`; 1: faithful, > 1 raises an
    inclusion's contrast for palpation training, keeping the order); ``stiffness_tau`` s: time constant of a
    first-order low-pass on the compliance model's stiffness (it follows the measured push depth, which
    carries the camera's noise; 0: none); ``max_dt`` s: longer gaps count as one nominal period;
    ``future_stamp_tolerance`` s: how far ahead of the caller's clock (``update``'s ``now``) a sample's stamp
    may be (clock offsets between hosts, a prediction horizon) before it is refused; ``pose_cutoff`` Hz: the
    corner of the low-pass on the fingertip that forms the sheet's orientation and contact point, so the
    finger's tremor does not turn the sheet (0: off; the push depth is not filtered), ``pose_velocity_cutoff``
    Hz: the corner of the smoothed velocity whose lead cancels that low-pass's lag
    (:class:`flexsheet.planning.pose_filter.PoseFilter`). The sheet's in-plane rotation ψ between touches
    (:class:`flexsheet.planning.pose_choice.PoseChoice`, with the arms' IK): candidates every ``psi_step`` rad
    within ±``psi_range`` rad of the paper's rule (0: the paper's rule alone), their look-ahead rolls up to
    ``psi_lookahead`` rad, a new choice only when better by ``psi_hysteresis`` (score units: a share of a
    joint's range), chosen every ``psi_period`` s. With ``use_mark``, while the finger is away and the
    application shows a target mark (:class:`flexsheet.planning.landing.Landing`): the sheet waits at it,
    ``preposition_offset`` m outside the object, closing onto it over ``preposition_blend`` m above
    ``touch_distance`` (the mark blends to the fingertip's own projection within ``touch_distance``); a mark
    older than ``mark_timeout`` s is not used. Raises ``ValueError`` on bad values."""

    touch_distance: float = 0.002
    release_distance: float = 0.006
    singular_eps: float = 1e-4
    jump_distance: float = 0.03
    recentre_time: float = 0.5
    u_ref: Vec = (0.0, 1.0, 0.0)
    sheet_margin: float = 0.03
    object_stiffness: float = 30.0
    stiffness_scale: float = 1.0
    contrast_gain: float = 1.0
    stiffness_tau: float = 0.1
    max_dt: float = 0.1
    future_stamp_tolerance: float = 0.5
    pose_cutoff: float = 3.0
    pose_velocity_cutoff: float = 3.0
    psi_step: float = math.radians(10.0)
    psi_range: float = math.radians(40.0)
    psi_lookahead: float = 0.6
    psi_hysteresis: float = 0.05
    psi_period: float = 0.1
    use_mark: bool = False
    preposition_offset: float = 0.003
    preposition_blend: float = 0.008
    mark_timeout: float = 1.0
    material: SheetMaterial = field(default_factory=SheetMaterial)
    limits: MotionLimits = field(default_factory=MotionLimits)
    reach: ReachModel = field(default_factory=ReachModel)

    def __post_init__(self) -> None:
        for k in ("touch_distance", "release_distance", "singular_eps", "jump_distance", "recentre_time",
                  "sheet_margin", "max_dt"):
            object.__setattr__(self, k, check_positive(k, getattr(self, k)))
        if self.release_distance < self.touch_distance:
            raise ValueError(f"release_distance must be >= touch_distance, got {self.release_distance!r}")
        if not (math.isfinite(self.object_stiffness) and self.object_stiffness >= 0.0):
            raise ValueError(f"object_stiffness must be finite and >= 0, got {self.object_stiffness!r}")
        if not (math.isfinite(self.stiffness_tau) and self.stiffness_tau >= 0.0):
            raise ValueError(f"stiffness_tau must be finite and >= 0 s, got {self.stiffness_tau!r}")
        if not (math.isfinite(self.future_stamp_tolerance) and 0.0 < self.future_stamp_tolerance <= 60.0):
            raise ValueError("future_stamp_tolerance must be in (0, 60] s, got "
                             f"{self.future_stamp_tolerance!r}")
        if not (math.isfinite(self.stiffness_scale) and 0.0 < self.stiffness_scale <= 100.0):
            raise ValueError(f"stiffness_scale must be in (0, 100], got {self.stiffness_scale!r}")
        if not (math.isfinite(self.contrast_gain) and 0.0 < self.contrast_gain <= 5.0):
            raise ValueError(f"contrast_gain must be in (0, 5], got {self.contrast_gain!r}")
        if not (math.isfinite(self.pose_cutoff) and 0.0 <= self.pose_cutoff <= 50.0):
            raise ValueError(f"pose_cutoff must be in [0, 50] Hz, got {self.pose_cutoff!r}")
        if not (math.isfinite(self.pose_velocity_cutoff) and 0.0 < self.pose_velocity_cutoff <= 50.0):
            raise ValueError(f"pose_velocity_cutoff must be in (0, 50] Hz, got {self.pose_velocity_cutoff!r}")
        if not (math.isfinite(self.psi_range) and 0.0 <= self.psi_range <= math.pi / 2 + 1e-9):
            raise ValueError(f"psi_range must be in [0, pi/2] rad, got {self.psi_range!r}")
        if not (math.isfinite(self.preposition_offset) and 0.0 <= self.preposition_offset <= 0.02):
            raise ValueError(f"preposition_offset must be in [0, 0.02] m, got {self.preposition_offset!r}")
        for k in ("psi_step", "psi_lookahead", "psi_period", "preposition_blend", "mark_timeout"):
            object.__setattr__(self, k, check_positive(k, getattr(self, k)))
        if not (math.isfinite(self.psi_hysteresis) and self.psi_hysteresis >= 0.0):
            raise ValueError(f"psi_hysteresis must be finite and >= 0, got {self.psi_hysteresis!r}")
        if len(self.u_ref) != 3 or not finite(self.u_ref) or norm(self.u_ref) < 1e-9:
            raise ValueError(f"u_ref must be a non-zero finite (3,) vector, got {self.u_ref!r}")
