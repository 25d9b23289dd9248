"""The sheet poses the planner commands, known to both sides: the inclined tangent plane at θ and the home
pose."""

from __future__ import annotations

import math

import numpy as np

from flexsheet.model import geometry


def inclined_pose(theta_deg: float, direction: str = "down") -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Commanded sheet pose (origin (3,) m, normal (3,), axis_u (3,)) = the cylinder's tangent plane at θ
    (deg), tilted ``direction`` ("down" or "up"). Raises ``ValueError`` for another direction or a non-finite
    θ."""
    if direction not in ("down", "up") or not math.isfinite(theta_deg):
        raise ValueError(f"need direction 'down'/'up' and a finite theta, got {direction!r}, {theta_deg!r}")
    R = geometry.CYLINDER_RADIUS
    sg = -1.0 if direction == "down" else 1.0
    th = math.radians(theta_deg)
    return (np.array([-R + R * math.cos(th), 0.0, sg * R * math.sin(th)]),
            np.array([math.cos(th), 0.0, sg * math.sin(th)]), np.array([0.0, 1.0, 0.0]))


HOME_POSE = (np.zeros(3), np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0]))
