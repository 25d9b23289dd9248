"""FEM messages: the deformed virtual object."""

from __future__ import annotations

from pydantic import Field

from messages.common import Message, ndarray

__all__ = ["ObjectDeformation", "ObjectForceDepth"]


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


class ObjectForceDepth(Message):
    """What the object asks the finger to feel, from the FEM model that deforms its image
    (:mod:`flexsheet.fem.force_depth`; :class:`flexsheet.model.force_depth.ForceDepth`). Latched; published
    once the FEM node's model is ready.

    ``points`` (P, 3) m, display frame: undeformed surface points along the scene's stroke (the first is the
    scene's ``reference``); ``normals`` (P, 3): their outward unit normals; ``names`` (P,); ``depths`` (D,) m
    ascending from 0; ``force`` (P, D) N: the contact force for a fingertip pushed that deep along −normal;
    ``scene_key``: the :meth:`flexsheet.model.scenes.Scene.key` of the object; ``method``: the model pushed.
    """

    SCHEMA = "flexsheet/ObjectForceDepth"
    VERSION = 1

    points: ndarray("float64", (None, 3), "surface points along the stroke, m, display frame")
    normals: ndarray("float64", (None, 3), "outward unit normals")
    names: list[str] = Field(description="point names; the first is 'reference'")
    depths: ndarray("float64", (None,), "push depths, m, ascending from 0")
    force: ndarray("float64", (None, None), "contact force per point and depth, N")
    scene_key: str = Field(default="", description="Scene.key() of the object")
    method: str = Field(default="", description="the FEM model pushed")
