"""The simulated viewer's head: a seeded slow sway, a scripted lean-in and occlusions of the glasses (twin
only).

A seated viewer's head is never still. :class:`HeadMotion` moves the cyclopean eye about the paper's V by a
sum of slow sinusoids per axis (a seated person's postural sway, 0.05–0.4 Hz, of centimetres: Kapteyn et al.
1983 report a few cm of head sway at the frequencies of postural control), turns the head by a few degrees the
same way, and plays a scripted lean-in toward the sheet and scripted occlusions of the glasses' markers (a
hand in front of the glasses). The viewer's own measurements — the true interpupillary distance and the true
eyes' offset in the glasses frame — are drawn per truth seed (:class:`Viewer`); the lab measures them with
their errors (:meth:`Viewer.measured`), and only those measurements reach the tracker.

Frames: ``display`` (:mod:`flexsheet.model.geometry`); the glasses frame of :mod:`flexsheet.calibration.eye`
(x from the right lens to the left lens, y up, z toward the sheet when worn). Units m, rad, s.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from flexsheet.model import geometry
from flexsheet.vision.glasses import GLASSES_AXES

__all__ = ["Viewer", "HeadState", "HeadMotion", "NOMINAL_EYE_OFFSET", "seeded_stream"]
#: the cyclopean eye in the glasses frame, m: 12 mm below the frame's bridge bar and 15 mm behind the lenses
NOMINAL_EYE_OFFSET = np.array([0.0, -0.012, -0.015])
#: adult interpupillary distance, m: mean 63 mm, s.d. 3.5 mm (Dodgson, Proc. SPIE 5291, 2004)
IPD_MEAN, IPD_SD = 0.063, 0.0035


def seeded_stream(seed: int, name: str) -> np.random.Generator:
    """A generator of its own per truth ``seed`` and ``name`` (drawing one thing never moves another's
    draws)."""
    return np.random.default_rng([int(seed), sum(ord(c) * 131 ** i for i, c in enumerate(name)) % (2**31)])


@dataclass(frozen=True)
class Viewer:
    """The viewer's true eyes: ``ipd`` m and ``eye_offset`` (3,) m in the glasses frame (how the glasses
    sit)."""

    ipd: float
    eye_offset: np.ndarray

    @classmethod
    def draw(cls, seed: int, realism: str = "realistic") -> Viewer:
        """The viewer of truth seed ``seed``; ``realism`` "ideal" gives the nominal viewer. Raises
        ``ValueError`` on an unknown realism."""
        if realism not in ("ideal", "realistic"):
            raise ValueError(f"realism must be 'ideal' or 'realistic', got {realism!r}")
        if realism == "ideal":
            return cls(IPD_MEAN, NOMINAL_EYE_OFFSET.copy())
        rng = seeded_stream(seed, "viewer")
        ipd = float(np.clip(rng.normal(IPD_MEAN, IPD_SD), 0.054, 0.072))
        return cls(ipd, NOMINAL_EYE_OFFSET + rng.normal(0.0, 0.003, 3))

    def measured_ipd(self, seed: int, sd: float = 0.0005) -> float:
        """The IPD as a lab's pupillometer reads it (± ``sd`` m, 0.5 mm by default), m."""
        return float(self.ipd + seeded_stream(seed, "pupillometer").normal(0.0, sd))


@dataclass(frozen=True)
class HeadState:
    """The head at one instant: ``T_display_glasses`` (4, 4); ``left``, ``right``, ``eye`` (3,) m;
    ``velocity`` (3,) m/s of the cyclopean eye; ``visible``: the glasses' markers are not occluded."""

    T_display_glasses: np.ndarray
    left: np.ndarray
    right: np.ndarray
    eye: np.ndarray
    velocity: np.ndarray
    visible: bool


@dataclass(frozen=True)
class HeadMotion:
    """The viewer's head over script time ``t`` s (see the module docstring).

    ``viewer``: the true eyes; ``seed``: the sway's phases and frequencies; ``sway`` (3,) m: the largest
    excursion of the cyclopean eye along x, y, z (default ±50, ±50, ±30 mm); ``turn`` (3,) rad: the largest
    roll, pitch and yaw; ``still``: no sway (the eye at ``home``). ``lean_in``: (start s, depth m toward the
    sheet, hold s), the eye ramping in over 1.5 s and back over 1.5 s (minimum jerk), or None; ``occlusions``:
    (start s, duration s) spans in which the markers are hidden. ``home`` (3,) m: the eye the sway is about
    (the paper's V). Raises ``ValueError`` on negative amplitudes, depths or durations.
    """

    viewer: Viewer
    seed: int = 0
    sway: tuple[float, float, float] = (0.05, 0.05, 0.03)
    turn: tuple[float, float, float] = (math.radians(2.0), math.radians(4.0), math.radians(6.0))
    still: bool = False
    lean_in: tuple[float, float, float] | None = None
    occlusions: tuple[tuple[float, float], ...] = ()
    home: np.ndarray = field(default_factory=lambda: geometry.EYE.copy())
    ramp: float = 1.5

    def __post_init__(self) -> None:
        if any(not (a >= 0.0 and math.isfinite(a)) for a in (*self.sway, *self.turn)):
            raise ValueError(f"sway and turn must be finite and >= 0, got {self.sway!r}, {self.turn!r}")
        if self.lean_in is not None and not all(v >= 0.0 and math.isfinite(v) for v in self.lean_in):
            raise ValueError(f"lean_in must be (start s, depth m, hold s), each >= 0, got {self.lean_in!r}")
        for span in self.occlusions:
            if len(span) != 2 or not (span[0] >= 0.0 and span[1] > 0.0):
                raise ValueError(f"occlusions must be (start s >= 0, duration s > 0) pairs, got {span!r}")
        rng = seeded_stream(self.seed, "head sway")
        # per channel (x, y, z, roll, pitch, yaw): three sinusoids, 0.05-0.4 Hz, weights summing to 1
        object.__setattr__(self, "_freq", rng.uniform(0.05, 0.4, (6, 3)))
        object.__setattr__(self, "_phase", rng.uniform(0.0, 2.0 * math.pi, (6, 3)))
        w = rng.uniform(0.5, 1.0, (6, 3))
        object.__setattr__(self, "_weight", w / w.sum(axis=1, keepdims=True))

    def _channels(self, t: float) -> np.ndarray:
        """(6,) sway values at ``t``: x, y, z m and roll, pitch, yaw rad."""
        if self.still:
            return np.zeros(6)
        amp = np.array([*self.sway, *self.turn])
        s = np.sin(2.0 * math.pi * self._freq * t + self._phase)
        return amp * (self._weight * s).sum(axis=1)

    def lean(self, t: float) -> float:
        """How far the eye has leaned toward the sheet at ``t``, m (0 outside the lean-in)."""
        if self.lean_in is None:
            return 0.0
        start, depth, hold = self.lean_in

        def mj(x: float) -> float:
            x = min(max(x, 0.0), 1.0)
            return x ** 3 * (10.0 - 15.0 * x + 6.0 * x * x)

        return depth * (mj((t - start) / self.ramp) - mj((t - start - self.ramp - hold) / self.ramp))

    def occluded(self, t: float) -> bool:
        """True while a scripted occlusion hides the glasses' markers at ``t``."""
        return any(s <= t < s + d for s, d in self.occlusions)

    def _pose(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        c = self._channels(t)
        eye = np.asarray(self.home, float) + c[:3] - [self.lean(t), 0.0, 0.0]
        rx, ry, rz = c[3:]
        Rx = np.array([[1, 0, 0], [0, math.cos(rx), -math.sin(rx)], [0, math.sin(rx), math.cos(rx)]])
        Ry = np.array([[math.cos(ry), 0, math.sin(ry)], [0, 1, 0], [-math.sin(ry), 0, math.cos(ry)]])
        Rz = np.array([[math.cos(rz), -math.sin(rz), 0], [math.sin(rz), math.cos(rz), 0], [0, 0, 1]])
        return eye, Rz @ Ry @ Rx @ GLASSES_AXES

    def state(self, t: float) -> HeadState:
        """The head at script time ``t`` s (before the script starts, pass 0)."""
        eye, R = self._pose(t)
        T = np.eye(4)
        T[:3, :3] = R
        T[:3, 3] = eye - R @ self.viewer.eye_offset
        h = 0.5 * self.viewer.ipd * R[:, 0]
        dt = 1e-3
        vel = (self._pose(t + dt)[0] - self._pose(t - dt)[0]) / (2.0 * dt)
        return HeadState(T, eye + h, eye - h, eye, vel, not self.occluded(t))
