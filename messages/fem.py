"""FEM messages: the deformed virtual object."""

from __future__ import annotations

from pydantic import Field

from messages.common import Message, ndarray

__all__ = ["ObjectDeformation"]


class ObjectDeformation(Message):
    """Deformed surface of the virtual object, from the FEM solver.

    ``vertices`` (N, 3) float32, m, display frame: deformed surface vertex positions. ``faces`` (M, 3)
    int32: surface triangles (indices into ``vertices``; constant for a given mesh). ``contact_force`` N:
    magnitude of the reaction on the fingertip (≥ 0). ``stiffness`` N/m: local stiffness dF/dd at the
    contact. ``depth`` m: push depth of the fingertip sphere into the undeformed surface. ``contact_point``
    (3,) m: undeformed surface point under the finger. ``method``: "condensed", "corotational", "sparse"…
    ``max_strain``: largest element strain (dimensionless). ``status``: "ok", "linear_invalid:<reason>",
    "nonlinear", "rejected:<reason>". ``valid`` False means vertices are the undeformed shape and must not be
    drawn as deformed. ``source_stamp``: exposure stamp of the source fingertip, s. ``scene_key``: the
    :meth:`flexsheet.model.scenes.Scene.key` of the object solved (SHA-256 hex; "" = unknown, e.g. a bag
    recorded before the FEM read scenes).
    """

    SCHEMA = "flexsheet/ObjectDeformation"
    VERSION = 1

    vertices: ndarray("float32", (None, 3), "deformed surface vertices, m, display frame")
    faces: ndarray("int32", (None, 3), "surface triangles")
    contact_force: float = Field(ge=0.0, description="fingertip reaction force, N")
    stiffness: float = Field(ge=0.0, description="local stiffness dF/dd, N/m")
    depth: float = Field(ge=0.0, description="push depth, m")
    contact_point: ndarray("float64", (3,), "undeformed contact point, m, display frame")
    method: str = Field(description="solver used for this update")
    max_strain: float = Field(default=0.0, ge=0.0, description="largest element strain")
    status: str = Field(default="ok", description="'ok' or the reason linear failed / input rejected")
    valid: bool = Field(default=True, description="False: do not draw as deformed")
    source_stamp: float = Field(default=0.0, description="exposure stamp of the source fingertip, s")
    scene_key: str = Field(default="", description="Scene.key() of the object solved; \"\" = unknown")
