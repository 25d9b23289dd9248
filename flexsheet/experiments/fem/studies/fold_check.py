"""The fold check of a reference path (:func:`fold_path`, cached): does its surface pass through itself or
crease (the reference has no self-contact), and its JSON form (:func:`fold_path_json`)."""

from __future__ import annotations

import math
import time

import numpy as np

from flexsheet.fem.cache import ArrayCache, cache_key
from flexsheet.fem.material import Material
from flexsheet.fem.reference.capsule_contact import capsule_at
from flexsheet.fem.reference.fold import (
    CREASE_STRETCH_RATIO,
    VERTEX_TOL,
    fold_report,
    lateral_distance,
    outer_surface,
)
from flexsheet.fem.reference.mesh import RefSpec
from flexsheet.fem.reference.paths import as_solved, check_dofs, reference_model
from flexsheet.fem.reference.settings import FINGER_R

FOLD_REGION = 0.03      #: m: surface points within this rest distance of the push axis are checked for folds
FOLD_VERSION = "fold-3"  #: bump when flexsheet/fem/reference/fold.py's checks change (fold_path's cache key)


def fold_path(spec: RefSpec, angle_deg: float, path: dict, depths: np.ndarray, mat: Material,
              cache: ArrayCache) -> dict:
    """Self-contact and crease check (:func:`flexsheet.fem.reference.fold.fold_report`) of every state of a
    :func:`reference_path` ``path`` (its ``u_dof``, at ``depths`` m) on ``spec``'s mesh at ``angle_deg``: the
    reference has no self-contact, so where its surface passes through itself it is not a physical solution.
    Cached (kind "fold", keyed by the states themselves). Returns (D,) arrays: "max_winding" (0.5 on a smooth
    surface, α/2π at the bottom of a fold of interior angle α, > 1 where the surface lies inside the body),
    "n_penetrating" (surface points with w > 1), "max_penetration" m, "min_stretch_ratio" (smallest in-plane
    stretch of the surface triangles off the footprint), "n_creased" (triangles below
    :data:`flexsheet.fem.reference.fold.CREASE_STRETCH_RATIO`), "worst_lateral" / "worst_drop" m (the
    largest-w point's rest distance from the push axis and its motion along the push); the same with the
    footprint included ("all_…": the material over the fingertip); "max_strain" the largest principal
    Green–Lagrange strain of any element and "max_strain_lateral_m" that element's rest distance from the push
    axis; "seconds". Raises ``RuntimeError`` when the re-made mesh has another DOF count than the path
    (:func:`check_dofs`)."""
    spec, angle_deg = as_solved(spec, angle_deg)
    ud = np.asarray(path["u_dof"])
    key = cache_key(FOLD_VERSION, spec.key(), angle_deg, np.round(depths, 9).tolist(), FOLD_REGION, FINGER_R,
                    CREASE_STRETCH_RATIO, VERTEX_TOL,
                    cache_key(np.ascontiguousarray(ud).tobytes()))

    def compute() -> dict:
        t = time.perf_counter()
        model = reference_model(spec, angle_deg, mat)
        check_dofs(path, model)
        surf = outer_surface(model)
        rows = []
        for j, d in enumerate(depths):
            caps = capsule_at(math.radians(angle_deg), float(d), FINGER_R, model.mesh.radius,
                              model.mesh.center)
            u = ud[j].reshape(-1, 3).astype(float)
            r = fold_report(model, surf, u, caps, FOLD_REGION)
            a = fold_report(model, surf, u, caps, FOLD_REGION, margin=-np.inf)     # the footprint too
            F = model.deformation(u)
            ev = np.linalg.eigvalsh(0.5 * (np.einsum("eqki,eqkj->eqij", F, F) - np.eye(3)))[...,
                                                                                            -1].max(axis=1)
            e = int(np.argmax(ev))
            r.update(all_max_winding=a["max_winding"], all_n_penetrating=a["n_penetrating"],
                     all_max_stretch_ratio=a["max_stretch_ratio"],
                     all_max_stretch_ratio_lateral_m=a["max_stretch_ratio_lateral_m"],
                     max_strain=float(ev[e]),
                     max_strain_lateral_m=float(lateral_distance(model.points[model.edofs[e]].mean(axis=0)[None],
                                                                  caps)[0]))
            rows.append(r)
        out = {k: np.array([r[k] if r[k] is not None else np.nan for r in rows], float)
               for k in ("max_winding", "n_penetrating", "max_penetration_m", "min_stretch_ratio",
                         "n_creased_tris",
                         "worst_lateral_m", "worst_drop_m", "all_max_winding", "all_n_penetrating",
                         "all_max_stretch_ratio", "all_max_stretch_ratio_lateral_m", "max_strain",
                         "max_strain_lateral_m")}
        out["seconds"] = np.array(time.perf_counter() - t)
        return out

    z, _, _ = cache.get_or_compute("fold", key, compute, f"fold check {spec.key()} at {angle_deg:g} deg")
    return z


def fold_path_json(f: dict) -> dict:
    """The JSON form of a :func:`fold_path` result (mm where a length)."""
    return {"max_winding": f["max_winding"].tolist(),
            "n_penetrating": f["n_penetrating"].astype(int).tolist(),
            "max_penetration_mm": (f["max_penetration_m"] * 1e3).tolist(),
            "min_stretch_ratio": f["min_stretch_ratio"].tolist(),
            "n_creased_tris": f["n_creased_tris"].astype(int).tolist(),
            "worst_lateral_mm": (f["worst_lateral_m"] * 1e3).tolist(),
            "worst_drop_mm": (f["worst_drop_m"] * 1e3).tolist(),
            "with_footprint": {"max_winding": f["all_max_winding"].tolist(),
                               "n_penetrating": f["all_n_penetrating"].astype(int).tolist(),
                               "max_stretch_ratio": f["all_max_stretch_ratio"].tolist(),
                               "max_stretch_ratio_rest_lateral_mm": (f["all_max_stretch_ratio_lateral_m"]
                                                                     * 1e3).tolist()},
            "max_principal_strain": f["max_strain"].tolist(),
            "max_strain_rest_lateral_mm": (f["max_strain_lateral_m"] * 1e3).tolist(),
            "seconds": float(f["seconds"])}
