"""The parts of a scene file (:mod:`flexsheet.model.scenes`), each a pydantic model that checks its own keys:
the object's pose and kind (cylinder, sphere, rounded box, mesh), its material, the support that holds it,
the finger, the declared use, the stroke (arc or polyline) and an inclusion. SI units (m, Pa, N); angles in
the file in degrees where the key says so."""

from __future__ import annotations

import math
from typing import Literal

import numpy as np
from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    field_validator,
    model_validator,
)

__all__ = ["SceneError", "Pose", "CylinderObject", "SphereObject", "RoundedBoxObject", "MeshObject",
           "MaterialSpec",
           "Support", "Finger", "Use", "ArcStroke", "PolylineStroke", "Inclusion", "rotation_rpy",
           "GENT_JM_RUBBER",
           "Vec3", "MAX_EXTENT", "SCENE_CONFIG"]


#: every surface point must lie within this distance of the display origin, m (the sheet is 240 mm square
#: and the arms reach ±60° tilts around objects of the cylinder's size)
MAX_EXTENT = 0.25


Vec3 = tuple[float, float, float]


#: the pydantic settings of every scene part: no unknown key, no inf or nan
SCENE_CONFIG = ConfigDict(extra="forbid", allow_inf_nan=False)


class SceneError(ValueError):
    """A scene file or value is invalid; the message names the file, the key and the value."""


def rotation_rpy(rpy_deg) -> np.ndarray:
    """R (3, 3) = Rz(yaw)·Ry(pitch)·Rx(roll) from (roll, pitch, yaw) in degrees; columns = local x, y, z axes
    in the display frame (the convention of :class:`flexsheet.model.shapes.RoundedBox`)."""
    r, p, y = np.radians(np.asarray(rpy_deg, dtype=float))
    cr, sr, cp, sp, cy, sy = math.cos(r), math.sin(r), math.cos(p), math.sin(p), math.cos(y), math.sin(y)
    Rz = np.array([[cy, -sy, 0.0], [sy, cy, 0.0], [0.0, 0.0, 1.0]])
    Ry = np.array([[cp, 0.0, sp], [0.0, 1.0, 0.0], [-sp, 0.0, cp]])
    Rx = np.array([[1.0, 0.0, 0.0], [0.0, cr, -sr], [0.0, sr, cr]])
    return Rz @ Ry @ Rx


def _nonzero(v: Vec3) -> Vec3:
    if float(np.linalg.norm(v)) <= 1e-12:
        raise ValueError(f"must be a non-zero vector, got {list(v)}")
    return v


# ----------------------------------------------------------------------------------------------- the schema
class Pose(BaseModel):
    """Placement of the object's local frame: ``position`` (3,) m (the object's centre, display frame) and
    ``rpy_deg`` (roll, pitch, yaw) degrees."""

    model_config = SCENE_CONFIG
    position: Vec3
    rpy_deg: Vec3 = (0.0, 0.0, 0.0)

    @property
    def R(self) -> np.ndarray:
        """Rotation (3, 3), local → display."""
        return rotation_rpy(self.rpy_deg)

    def apply(self, local) -> np.ndarray:
        """Display-frame points (N, 3) float64 of local points (N, 3)."""
        return np.asarray(local, dtype=float) @ self.R.T + np.asarray(self.position, dtype=float)


class CylinderObject(BaseModel):
    """Capped circular cylinder: ``radius``, ``length`` m; local axis +y."""

    model_config = SCENE_CONFIG
    kind: Literal["cylinder"]
    radius: float = Field(gt=0.0, le=0.2, description="m")
    length: float = Field(gt=0.0, le=0.4, description="m")
    pose: Pose


class SphereObject(BaseModel):
    """Sphere of ``radius`` m."""

    model_config = SCENE_CONFIG
    kind: Literal["sphere"]
    radius: float = Field(gt=0.0, le=0.2, description="m")
    pose: Pose


class RoundedBoxObject(BaseModel):
    """Box of outer ``half_extents`` (3,) m with edges rounded by ``radius`` m (0: sharp; ≤ the smallest
    half extent)."""

    model_config = SCENE_CONFIG
    kind: Literal["rounded_box"]
    half_extents: Vec3
    radius: float = Field(0.0, ge=0.0, description="edge radius, m")
    pose: Pose

    @field_validator("half_extents")
    @classmethod
    def _positive(cls, v: Vec3) -> Vec3:
        if min(v) <= 0.0 or max(v) > 0.2:
            raise ValueError(f"must be 3 half extents in (0, 0.2] m, got {list(v)}")
        return v

    @model_validator(mode="after")
    def _radius_fits(self) -> RoundedBoxObject:
        if self.radius > min(self.half_extents):
            raise ValueError(f"radius {self.radius} m is larger than the smallest half extent "
                             f"{min(self.half_extents)} m")
        return self


class MeshObject(BaseModel):
    """A closed surface mesh file (OBJ, STL, PLY, OFF… through trimesh; other formats through meshio), path
    relative to the scene file; ``scale`` converts its units to m (0.001 for a file in mm)."""

    model_config = SCENE_CONFIG
    kind: Literal["mesh"]
    file: str = Field(min_length=1)
    scale: float = Field(1.0, gt=0.0)
    pose: Pose = Pose(position=(0.0, 0.0, 0.0))


#: Gent's limiting chain extensibility (the largest I₁ − 3) for natural rubber, fitted to
#: Treloar's data (Gent, Rubber Chem. Technol. 69, 1996; the value used by Horgan & Saccomandi,
#: Math. Mech. Solids 7, 2002 — recalled, not re-fitted here): the *weakest* strain-stiffening of
#: the published fits (soft tissues fit far smaller Jm, i.e. stiffen sooner), so the Gent solid
#: closest to neo-Hookean that still has a limiting stretch (equibiaxial λ ≤ 7.1, uniaxial ≤ 9.9).
#: The paper's cylinder (:func:`paper_scene`, ``cylinder.yaml``) is this solid: a neo-Hookean body
#: under the paper's 50 mm push has no mesh-converged solution at the fingertip (docs/fem.md)
GENT_JM_RUBBER = 97.2


class MaterialSpec(BaseModel):
    """Hyperelastic material of the object: ``model`` (``neo_hookean``, the default; ``gent``, a
    strain-stiffening solid with limiting extensibility ``Jm`` = the largest I₁ − 3, Gent 1996, which needs
    ``Jm``; or ``linear`` small-strain elasticity), Young's modulus ``E`` Pa and Poisson's ratio ``nu`` (the
    small-strain limits of either law: μ = E/(2(1+ν)), λ = Eν/((1+ν)(1−2ν))). Raises ``ValueError`` (pydantic)
    for ``gent`` without ``Jm`` or ``Jm`` with another model."""

    model_config = SCENE_CONFIG
    model: Literal["neo_hookean", "gent", "linear"] = "neo_hookean"
    E: float = Field(10e3, gt=0.0, le=1e9, description="Pa")
    nu: float = Field(0.45, ge=0.0, lt=0.5)
    Jm: float | None = Field(None, gt=0.0, le=1e6, description="Gent limiting I1 - 3 (dimensionless)")

    @model_validator(mode="after")
    def _jm(self) -> MaterialSpec:
        if self.model == "gent" and self.Jm is None:
            raise ValueError("model gent needs Jm (its limiting I1 - 3, e.g. 97.2 for natural rubber)")
        if self.model != "gent" and self.Jm is not None:
            raise ValueError(f"Jm is a Gent parameter; model {self.model!r} takes none")
        return self


class Support(BaseModel):
    """How the object rests: boundary points with (p − point)·normal ≤ ``tolerance`` are fixed.

    ``back_half``: ``point`` = the object's centre, ``normal`` = +x (toward the user) — the half of the
    surface away from the user is held (the paper's cylinder lying on its back; the FEM's original rule).
    ``half_space``: explicit ``point`` (3,) m and ``normal`` (3,) (e.g. a base face: a point on it, normal
    pointing into the body)."""

    model_config = SCENE_CONFIG
    kind: Literal["back_half", "half_space"] = "back_half"
    point: Vec3 | None = None
    normal: Vec3 = (1.0, 0.0, 0.0)
    tolerance: float = Field(1e-9, ge=0.0, le=0.05, description="m")

    @field_validator("normal")
    @classmethod
    def _normal(cls, v: Vec3) -> Vec3:
        return _nonzero(v)

    @model_validator(mode="after")
    def _point(self) -> Support:
        if self.kind == "half_space" and self.point is None:
            raise ValueError("kind half_space needs a point")
        if self.kind == "back_half" and self.point is not None:
            raise ValueError("kind back_half takes its point from the object's centre; use half_space")
        return self


class Finger(BaseModel):
    """The user's fingertip as the FEM and the world see it: a sphere of ``radius`` m, and how the object's
    surface meets it in the nonlinear reference (``contact``,
    :data:`flexsheet.fem.reference.capsule_contact.CONTACT_LAWS`): ``frictionless`` (the default: the surface
    slides freely over the fingertip) or ``sticking`` (a fingertip that does not slip on the skin: a surface
    point that touched it moves with it). A modelling choice per
    object: the rounded box's push beside its edge has a sliding mode under a frictionless fingertip that no
    Newton solve on its quick mesh got past 25 mm, and skin does not slide on silicone."""

    model_config = SCENE_CONFIG
    radius: float = Field(0.008, ge=0.001, le=0.03, description="m")
    contact: Literal["frictionless", "sticking"] = Field("frictionless", description="reference contact law")
    contact_source: str = Field("", max_length=400, description="why this law: the cited source")


class Use(BaseModel):
    """The depths the scene is used at, and why: its FEM is judged over pushes 0…``max_depth`` m (at least
    15 mm: palpating a soft body for a stiffer inclusion presses well past the first millimetres); its stroke
    experiments press ``stroke_depth`` m (≤ ``max_depth``). Not part of the FEM's cache key."""

    model_config = SCENE_CONFIG
    max_depth: float = Field(0.05, ge=0.015, le=0.06, description="m")
    stroke_depth: float = Field(0.010, ge=0.0, le=0.06, description="m")
    reason: str = Field("", max_length=600)

    @model_validator(mode="after")
    def _order(self) -> Use:
        if self.stroke_depth > self.max_depth:
            raise ValueError(f"stroke_depth {self.stroke_depth} m exceeds max_depth {self.max_depth} m")
        return self


class ArcStroke(BaseModel):
    """A stroke swept by a ray from ``center`` (default: the object's centre) whose direction turns from
    ``start`` (angle 0) toward ``toward`` (angle 90°) between ``start_deg`` and ``end_deg``; each ray's exit
    from the body is a point of the path. The paper's stroke: start +x (facing the user), toward +z, 0–60°."""

    model_config = SCENE_CONFIG
    kind: Literal["arc"]
    center: Vec3 | None = None
    start: Vec3 = (1.0, 0.0, 0.0)
    toward: Vec3 = (0.0, 0.0, 1.0)
    start_deg: float = Field(0.0, ge=-360.0, le=360.0)
    end_deg: float = Field(60.0, ge=-360.0, le=360.0)

    @field_validator("start", "toward")
    @classmethod
    def _dir(cls, v: Vec3) -> Vec3:
        return _nonzero(v)

    @model_validator(mode="after")
    def _frame(self) -> ArcStroke:
        a, b = np.asarray(self.start, float), np.asarray(self.toward, float)
        if np.linalg.norm(np.cross(a, b)) <= 1e-6 * np.linalg.norm(a) * np.linalg.norm(b):
            raise ValueError(f"start {list(self.start)} and toward {list(self.toward)} are parallel")
        if abs(self.end_deg - self.start_deg) < 1e-6:
            raise ValueError(f"end_deg equals start_deg ({self.start_deg}): an empty stroke")
        return self

    def basis(self) -> tuple[np.ndarray, np.ndarray]:
        """(e0, e1): unit directions at angles 0 and 90° (Gram–Schmidt of ``start``, ``toward``)."""
        e0 = np.asarray(self.start, float) / np.linalg.norm(self.start)
        t = np.asarray(self.toward, float)
        e1 = t - (t @ e0) * e0
        return e0, e1 / np.linalg.norm(e1)


class PolylineStroke(BaseModel):
    """A stroke through ``points`` (≥ 2, (3,) m each, display frame, outside the body, e.g. just in front of
    the surface); the straight segments between them are projected onto the surface (closest point)."""

    model_config = SCENE_CONFIG
    kind: Literal["polyline"]
    points: list[Vec3] = Field(min_length=2, max_length=256)

    @field_validator("points")
    @classmethod
    def _distinct(cls, v: list[Vec3]) -> list[Vec3]:
        p = np.asarray(v, float)
        seg = np.linalg.norm(np.diff(p, axis=0), axis=1)
        if np.any(seg < 1e-6):
            i = int(np.argmin(seg))
            raise ValueError(f"points {i} and {i + 1} coincide ({list(v[i])})")
        return v


class Inclusion(BaseModel):
    """A stiffer sphere inside the body (a "tumour" palpation should find): ``center`` (3,) m, ``radius`` m,
    ``E`` Pa, ``nu`` (None: the body's)."""

    model_config = SCENE_CONFIG
    name: str = "inclusion"
    center: Vec3
    radius: float = Field(gt=0.0, le=0.1, description="m")
    E: float = Field(gt=0.0, le=1e9, description="Pa")
    nu: float | None = Field(None, ge=0.0, lt=0.5)
