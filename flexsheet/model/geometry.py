"""The paper's display geometry in the ``display`` frame, shared by every node (pure, no I/O).

Frame ``display``: origin at the centre of the sheet in its home pose (the paper's imaginary screen), +x from
the sheet toward the user (screen normal n_o), +y to the user's right (the user faces −x), +z up. Units m,
rad. Note: the design card names +y "the user's left", but a right-handed frame with +x toward the user and +z
up has +y on the user's *right* (the user faces −x). All code uses right-handed coordinates and only the
coordinates; the scene is symmetric in y, so the only effect is naming: the "left" arm/clamp is the one at +y.

Sheet frame convention (used by :class:`messages.SheetTarget`, the planner, the arm bridges and the world;
the functions that map it to the clamps and back live in :mod:`flexsheet.model.sheet`):
``axis_u`` points from the right clamp to the left clamp (+y at home), ``axis_v = normal × axis_u``
(+z at home) and ``normal`` points toward the user (+x at home), so (normal, axis_u, axis_v) is right-handed.
A clamp frame (the arms' tool frame, ``T_display_clamp``) sits at the middle of its clamped edge with the
same orientation as the sheet: columns of R are (normal, axis_u, axis_v).

Sources: Furukawa et al., §IV and §VI-A (eye 400 mm in front, projector 1000 mm behind and 250 mm below,
cylinder Ø 50√2 mm × 120 mm, sheet 240 × 240 × 1 mm urethane rubber).
"""

from __future__ import annotations

import math

import numpy as np

__all__ = [
    "EYE", "PROJECTOR", "SCREEN_POINT", "SCREEN_NORMAL", "CYLINDER_RADIUS", "CYLINDER_LENGTH",
    "CYLINDER_CENTER", "CYLINDER_AXIS", "SHEET_SIZE", "SHEET_THICKNESS", "PIXEL_ON_SCREEN", "LEFT_BASE",
    "RIGHT_BASE", "pose_matrix",
]

EYE = np.array([0.400, 0.0, 0.0])                       #: user's eye V (cyclopean), m
PROJECTOR = np.array([-1.000, 0.0, -0.250])             #: projector light source P, m
SCREEN_POINT = np.zeros(3)                              #: r_o, a point of the imaginary screen, m
SCREEN_NORMAL = np.array([1.0, 0.0, 0.0])               #: n_o, imaginary screen normal (toward the user)
CYLINDER_RADIUS = 0.025 * math.sqrt(2.0)                #: R, m (diameter 50√2 mm)
CYLINDER_LENGTH = 0.120                                 #: m
CYLINDER_CENTER = np.array([-CYLINDER_RADIUS, 0.0, 0.0])  #: O, on the axis, m
CYLINDER_AXIS = np.array([0.0, 1.0, 0.0])               #: axis direction (horizontal, along y)
SHEET_SIZE = 0.240                                      #: sheet side, m (square)
SHEET_THICKNESS = 0.001                                 #: m
PIXEL_ON_SCREEN = 0.0007                                #: one projector pixel on the imaginary screen, m

#: the arm base poses (x, y, z, yaw) in the display frame, the one copy (flexsheet.arm.kinematics and the
#: planner's reach model import them): the arms face each other across the sheet,
#: J1 axes 0.55 m to either side of the sheet centre, bases 0.40 m below it. Checked with the RV-1A's IK
#: (flexsheet/arm/kinematics.py): the home sheet and tilts of ±60° about the cylinder axis with stretch
#: 0…0.1 are reachable with ≥ 20° joint margin (closer bases need J3 beyond its 155° limit).
LEFT_BASE = (-0.05, 0.55, -0.40, -math.pi / 2)
RIGHT_BASE = (-0.05, -0.55, -0.40, math.pi / 2)


def pose_matrix(x: float, y: float, z: float, yaw: float) -> np.ndarray:
    """4×4 homogeneous transform for a translation (m) and a yaw about +z (rad). Returns (4, 4) float64."""
    c, s = math.cos(yaw), math.sin(yaw)
    T = np.eye(4)
    T[:3, :3] = [[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]
    T[:3, 3] = (x, y, z)
    return T

