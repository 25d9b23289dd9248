"""The scene reference: the scene's compressible hyperelastic body pushed by its capsule finger along the
inward normal (:func:`scene_reference`), cached, and the settings of its judged pushes (:data:`QUICK`,
:data:`FULL`). The path tables (:mod:`flexsheet.fem.reference.path_table`) and the scene study
(:mod:`flexsheet.experiments.fem_scene`) solve it.
"""

from __future__ import annotations

import logging
import time

import numpy as np

from flexsheet.fem.cache import cache_key
from flexsheet.fem.material import Material
from flexsheet.fem.mesh import MeshSpec
from flexsheet.fem.path_snapshots import GRID
from flexsheet.fem.reference.capsule_contact import Capsule
from flexsheet.fem.reference.hyperelastic import HyperelasticModel
from flexsheet.fem.reference.path_solver import solve_path_capsule
from flexsheet.fem.reference.versions import SOLVER_VERSION
from flexsheet.fem.scene_mesh import scene_mesh

log = logging.getLogger(__name__)

__all__ = ["scene_reference", "QUICK", "FULL"]

#: settings: push fractions along the stroke, recorded depths (m), load step (m), reference levels' h_fine (m,
#: coarse to fine, ratio 4/3 for the grid convergence index), path refinement (True: down to the scene's
#: use.max_depth), the support's rim on a mesh line (:func:`flexsheet.fem.scene_mesh.scene_mesh`)
QUICK = {"fractions": (0.5,), "depths": tuple(np.round(np.arange(1, 7) * 0.005, 4)), "step": 0.0025,
         "levels": (0.008, 0.006, 0.0045), "h": 0.012, "refine_radius": 0.015, "path_depth": True,
         "rim": True,
         "n_time": 100}
#: the full run: its first level is the path table's stations' mesh
#: (:data:`flexsheet.fem.path_snapshots.GRID`), with the same outputs, so its pushes at the stroke's start,
#: middle and end are those of a path table whose stations include them (any odd count: the default 13, or 7)
FULL = {"fractions": (0.0, 0.5, 1.0),
        "depths":
            tuple(np.round(np.arange(1, int(round(GRID["depth_max"] / GRID["step"])) + 1) * GRID["step"], 9)),
        "step": GRID["step"], "levels": (GRID["h_fine"], 0.004, 0.003), "h": GRID["h"],
        "refine_radius": GRID["refine_radius"], "path_depth": GRID["path_depth"], "n_time": 300}


def scene_reference(sc, q: np.ndarray, n: np.ndarray, h_fine: float, st: dict, probes: np.ndarray,
                    cache) -> dict:
    """The scene's hyperelastic push (its material, its finger's contact law) at surface point ``q`` (3,) m
    along −``n`` (outward unit normal (3,)) through ``st['depths']`` (D,) m (load steps ``st['step']``) on a
    mesh of size ``st['h']`` refined to ``h_fine`` m within ``st['refine_radius']`` of ``q``
    (``st['path_depth']`` > 0: of the whole push path down to that depth; ``st['rim']``: the support's rim a
    refined mesh line); cached (kind "scenereference"). Returns arrays: ``u`` (D, k, 3) m the displacements at
    ``probes`` (k, 3) m, ``force`` (D,) N, ``converged``, ``inverted``, ``max_strain`` (D,) (largest principal
    Green–Lagrange strain), ``seconds``, ``dofs``, and the mesh (``points``, ``tets``, ``fixed``, ``E``,
    ``nu``)."""
    depths = np.asarray(st["depths"], float)
    path = float(st.get("path_depth", 0.0))
    rim = bool(st.get("rim", False))
    key = cache_key("scene-ref-2", SOLVER_VERSION, sc.key(), h_fine, st["h"], st["refine_radius"], st["step"],
                    np.round(q, 9).tolist(), np.round(n, 9).tolist(), np.round(depths, 9).tolist(),
                    cache_key(np.round(probes, 9).tobytes()), *([f"path={path:.6g}"] if path > 0 else []),
                    *(["rim"] if rim else []))
    # refine around the push point, or (path_depth > 0) along the whole push path: balls every
    # refine_radius/3 from q down to path_depth along -n (the tube the finger travels through)
    steps = np.arange(0.0, path + 1e-12, st["refine_radius"] / 3) if path > 0 else np.zeros(1)
    refine_at = q[None] - steps[:, None] * n[None]

    def compute() -> dict:
        t = time.perf_counter()
        sm = scene_mesh(sc, MeshSpec(st["h"], h_fine, st["refine_radius"]), refine_at=refine_at, rim=rim)
        mat = Material.of_scene(sc.material)
        m0 = HyperelasticModel(sm.mesh, mat, sym_y=False, sym_z=False, E_elem=sm.E, nu_elem=sm.nu)
        model = HyperelasticModel(sm.mesh, mat, sym_y=False, sym_z=False,
                                  support=m0.dof_points(sm.mesh.fixed),
                                  E_elem=sm.E, nu_elem=sm.nu)
        r = sc.finger.radius
        log.info(f"reference h_fine {h_fine * 1e3:g} mm at {np.round(q * 1e3, 1).tolist()} mm: {model.n} DOF "
                 "...")
        states = solve_path_capsule(model, lambda d: Capsule(q - d * n + r * n, -n, r), depths,
                                    step=st["step"], label=f"scene {sc.name}",
                                    contact=sc.finger.contact)
        P = model.probe_matrix(probes)
        return {"u": np.stack([np.asarray(P @ s.u) for s in states]),
                "force": np.array([s.force for s in states]),
                "converged": np.array([s.converged for s in states]),
                "inverted": np.array([s.inverted for s in states]),
                "max_strain": np.array([s.max_strain for s in states]),
                "seconds": np.array(time.perf_counter() - t), "dofs": np.array(model.n),
                "points": sm.mesh.points, "tets": sm.mesh.tets, "fixed": sm.mesh.fixed, "E": sm.E,
                "nu": sm.nu}

    z, _, _ = cache.get_or_compute("scenereference", key, compute, f"scene reference h_fine {h_fine * 1e3:g} "
                                                                   "mm")
    return z
