"""Which eyes a stereo pair is corrected for: the tracked viewer's, predicted to photon time, or the fixed V.

The correction (paper eqs 1–6) is exact for the eye it is given. :class:`Viewpoint` keeps the newest tracked
eyes (``/eye/pose``, :class:`messages.EyePose`) and answers, for the moment a frame will be on the sheet:

* ``tracked``: the newest valid pose's eyes moved on by its velocity to that moment (at most
  ``max_extrapolation`` s ahead: a pose older than that is not moved further);
* ``held``: the glasses are lost (an invalid pose, or none for ``timeout`` s): the last good pose, unmoved,
  for ``hold`` s after it was taken;
* ``fixed``: no tracked pose yet, or lost for longer than ``hold``: the registered viewpoint V ± IPD/2.

Each change of source is returned once by :meth:`Viewpoint.eyes` as a line to log. Units m, s; display frame.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["Viewpoint", "ViewpointChoice"]


@dataclass(frozen=True)
class ViewpointChoice:
    """``left``, ``right`` (3,) m: the eyes to draw for; ``source``: "tracked", "held" or "fixed"; ``say``: a
    line to log when the source changed with this call (else "")."""

    left: np.ndarray
    right: np.ndarray
    source: str
    say: str = ""


def _vec3(name: str, v) -> np.ndarray:
    a = np.asarray(v, float).ravel()
    if a.shape != (3,) or not np.all(np.isfinite(a)):
        raise ValueError(f"{name} must be 3 finite numbers, got {v!r}")
    return a


class Viewpoint:
    """See the module docstring. ``fixed_left``/``fixed_right`` (3,) m: the eyes at the registered V; ``hold``
    s: how long the last good pose is kept once lost; ``timeout`` s: a valid pose older than this counts as
    lost; ``max_extrapolation`` s. Raises ``ValueError`` on non-finite eyes or non-positive times."""

    def __init__(self, fixed_left, fixed_right, *, hold: float = 2.0, timeout: float = 0.1,
                 max_extrapolation: float = 0.1) -> None:
        self.fixed = (_vec3("fixed_left", fixed_left), _vec3("fixed_right", fixed_right))
        for name, v in (("hold", hold), ("timeout", timeout), ("max_extrapolation", max_extrapolation)):
            if not (np.isfinite(v) and v > 0.0):
                raise ValueError(f"{name} must be > 0 s, got {v!r}")
        self.hold, self.timeout, self.max_extrapolation = (float(hold), float(timeout),
                                                           float(max_extrapolation))
        # stamp, left, right, velocity
        self._good: tuple[float, np.ndarray, np.ndarray, np.ndarray] | None = None
        self._lost_since: float | None = None
        self._source = ""            # said on the first call too
        self.counts = {"tracked": 0, "held": 0, "fixed": 0}

    def update(self, stamp: float, left, right, velocity, valid: bool) -> None:
        """One ``/eye/pose``: its mid-exposure ``stamp`` s, the eyes (3,) m and the eye velocity (3,) m/s, and
        whether the glasses were found. Raises ``ValueError`` on non-finite values (the last good pose
        stays)."""
        if not np.isfinite(stamp):
            raise ValueError(f"stamp must be finite, got {stamp!r}")
        if not valid:
            if self._lost_since is None:
                self._lost_since = float(stamp)
            return
        self._good = (float(stamp), _vec3("left", left), _vec3("right", right), _vec3("velocity", velocity))
        self._lost_since = None

    def eyes(self, t: float) -> ViewpointChoice:
        """The eyes to correct a frame for that will be on the sheet at ``t`` s (see the module docstring)."""
        good = self._good
        if good is None:
            choice = ViewpointChoice(*self.fixed, "fixed")
        else:
            stamp, left, right, vel = good
            lost = self._lost_since is not None or t - stamp > self.timeout + self.max_extrapolation
            if not lost:
                dt = min(max(t - stamp, 0.0), self.max_extrapolation)
                choice = ViewpointChoice(left + vel * dt, right + vel * dt, "tracked")
            elif t - stamp <= self.hold:
                choice = ViewpointChoice(left, right, "held")
            else:
                choice = ViewpointChoice(*self.fixed, "fixed")
        self.counts[choice.source] += 1
        if choice.source != self._source:
            say = {"tracked": "drawing for the tracked eyes (/eye/pose)",
                   "held": "glasses lost: drawing for their last good pose",
                   "fixed": "no tracked eyes: drawing for the fixed viewpoint V"}[choice.source]
            self._source = choice.source
            return ViewpointChoice(choice.left, choice.right, choice.source, say)
        return choice
