"""Model no more than the scene needs: pick the coarsest mesh and smallest refined band that meet the accuracy
target over the push-depth range (pure; the accuracy table comes from ``flexsheet experiment fem``).

Accuracy of a candidate (mesh, element order) = largest surface-displacement error (m) of its solution
against the P2 reference on the finest mesh, over the rendered (free) surface vertices outside the finger's
footprint (lateral distance from the push axis > finger radius + 2 mm; the footprint is hidden by the finger
and its rim error is reported separately), at each push depth. Cost = DOF count. Because contact
is displacement-driven, that error does not depend on E (only on ν and the finger radius), so one table
serves every E. The shipped table is ``flexsheet/fem/accuracy_table.json``.
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass

import numpy as np

from flexsheet.fem.contact import finger_at
from flexsheet.fem.material import Material
from flexsheet.fem.mesh import MeshSpec, cylinder_tet_mesh
from flexsheet.fem.solver import FemModel, solve_full

__all__ = ["Choice", "evaluate_spec", "choose", "load_table", "visible_mask", "TABLE_PATH", "DEFAULT_SPEC",
           "DEFAULT_ORDER", "choose_fem_model", "load_model_table", "MODEL_TABLE_PATH", "MODEL_PREFERENCE"]

TABLE_PATH = os.path.join(os.path.dirname(__file__), "accuracy_table.json")
MODEL_TABLE_PATH = os.path.join(os.path.dirname(__file__), "model_table.json")
#: simplest first: linear needs no nonlinear precompute; the
#: snapshots need the (cached or shipped) hyperelastic table
MODEL_PREFERENCE = ("linear", "corotational", "snapshots")
DEFAULT_SPEC = MeshSpec(0.012, 0.004, 0.012)
DEFAULT_ORDER = 2


@dataclass(frozen=True)
class Choice:
    """Chosen mesh ``spec`` and element ``order`` (1 or 2), its worst surface error ``error`` (m) over the
    depth range (nan if unknown), ``met`` whether the target is met, and ``reason`` (one line for the start-up
    log)."""

    spec: MeshSpec
    order: int
    error: float
    met: bool
    reason: str


def visible_mask(points: np.ndarray, finger, margin: float = 0.002) -> np.ndarray:
    """(k,) bool: points whose lateral distance from the push axis exceeds finger radius + ``margin`` (m),
    i.e. outside the finger's footprint, where the rendered surface is not hidden by the finger."""
    rel = np.asarray(points, float) - finger.center
    a = rel @ finger.direction
    lat = np.sqrt(np.maximum(np.einsum("ij,ij->i", rel, rel) - a * a, 0.0))
    return lat > finger.radius + margin


def evaluate_spec(spec: MeshSpec, ref_model: FemModel, ref_solutions: dict, material: Material,
                  finger_radius: float, order: int = 1) -> dict:
    """Errors of the P``order`` model on ``spec`` against reference solutions.

    ``ref_solutions`` maps depth (m) → reference :class:`~flexsheet.fem.solver.Solution` (with ``u_full``) on
    ``ref_model`` (P2, finger at azimuth 0). Errors are taken at the rendered vertices (free surface mesh
    nodes). Returns {"spec", "order", "mesh_nodes", "dofs", "surface_error_m": {depth: max error outside the
    finger footprint, m}, "surface_error_all_m": {depth: max over all vertices}, "surface_rms_m",
    "force_error_pct", "force_N"}; depth keys are "%.4f" m.
    """
    mesh = cylinder_tet_mesh(spec)
    model = FemModel(mesh, material, order=order)
    surf = np.flatnonzero(model.boundary & ~model.fixed)
    surf = surf[surf < len(mesh.points)]
    out = {"spec": spec.__dict__, "order": order, "mesh_nodes": int(len(mesh.points)), "dofs": model.n_dofs,
           "surface_error_m": {}, "surface_error_all_m": {}, "surface_rms_m": {}, "force_error_pct": {},
           "force_N": {}}
    for d, ref in sorted(ref_solutions.items()):
        fg = finger_at(0.0, d, finger_radius, mesh.radius, mesh.center)
        sol = solve_full(model, fg)
        u_ref = ref_model.probe(model.points[surf], ref.u_full)
        err = np.linalg.norm(sol.u[surf] - u_ref, axis=1)
        vis = visible_mask(model.points[surf], fg)
        key = f"{d:.4f}"
        out["surface_error_m"][key] = float(err[vis].max())
        out["surface_error_all_m"][key] = float(err.max())
        out["surface_rms_m"][key] = float(np.sqrt(np.mean(err ** 2)))
        out["force_error_pct"][key] = (float(100.0 * (sol.force - ref.force) / ref.force) if ref.force > 0
                                       else 0.0)
        out["force_N"][key] = float(sol.force)
    return out


def choose(table: dict | None, target: float, depth_min: float, depth_max: float, nu: float,
           finger_radius: float) -> Choice:
    """Cheapest (fewest DOFs) table entry whose surface error ≤ ``target`` (m) at every tabulated depth in
    [depth_min, depth_max] (m). Falls back to :data:`DEFAULT_SPEC` when the table is missing or was made for
    another ν / finger radius; to the most accurate entry when none meets the target. Raises ``ValueError``
    on a non-positive target or an empty depth range."""
    if not (math.isfinite(target) and target > 0):
        raise ValueError(f"accuracy target must be > 0 m, got {target!r}")
    if not (0 <= depth_min <= depth_max):
        raise ValueError(f"depth range must satisfy 0 <= min <= max, got [{depth_min!r}, {depth_max!r}]")
    if not table:
        return Choice(DEFAULT_SPEC, DEFAULT_ORDER, float("nan"), False,
                      "no accuracy table: default mesh " + DEFAULT_SPEC.key())
    if abs(table.get("nu", -1) - nu) > 1e-6 or abs(table.get("finger_radius", -1) - finger_radius) > 1e-9:
        return Choice(DEFAULT_SPEC, DEFAULT_ORDER, float("nan"), False,
                      f"accuracy table is for nu={table.get('nu')}, "
                      f"finger_radius={table.get('finger_radius')} m; default mesh {DEFAULT_SPEC.key()}")
    rows = []
    for e in table["candidates"]:
        errs = [v for k,
                v in e["surface_error_m"].items() if depth_min - 1e-9 <= float(k) <= depth_max + 1e-9]
        if not errs:
            continue
        rows.append((max(errs), e.get("dofs", e["mesh_nodes"]), MeshSpec(**e["spec"]), e.get("order", 1)))
    if not rows:
        return Choice(DEFAULT_SPEC, DEFAULT_ORDER, float("nan"), False,
                      "no tabulated depth in range: default mesh")
    ok = [r for r in rows if r[0] <= target]
    if ok:
        err, n, spec, order = min(ok, key=lambda r: (r[1], r[0]))
        return Choice(spec, order, err, True, f"chose P{order} {spec.key()} ({n} DOF): worst surface error "
                                       f"{err * 1e3:.2f} mm <= target {target * 1e3:.2f} mm over depths "
                                       f"{depth_min * 1e3:.0f}-{depth_max * 1e3:.0f} mm")
    err, n, spec, order = min(rows, key=lambda r: r[0])
    return Choice(spec, order, err, False, f"target {target * 1e3:.2f} mm not met by any tabulated mesh; "
                                           f"most accurate P{order} {spec.key()} ({n} DOF) has "
                                           f"{err * 1e3:.2f} mm")


def choose_fem_model(table: dict | None, target: float, depth_max: float, update_ms_max: float = 1.0
                     ) -> tuple[str, str]:
    """(model kind, reason): the first of :data:`MODEL_PREFERENCE` whose largest visible-surface error against
    the nonlinear reference, over every tabulated contact position and depth ≤ ``depth_max`` (m), is within
    ``target`` (m) at ≤ ``update_ms_max`` ms per update; the most accurate one when none is. ``table`` is
    ``flexsheet/fem/model_table.json`` (written by ``flexsheet experiment fem``); without it: "snapshots".
    Raises ``ValueError`` on a non-positive target or depth."""
    if not (math.isfinite(target) and target > 0):
        raise ValueError(f"accuracy target must be > 0 m, got {target!r}")
    if not (math.isfinite(depth_max) and depth_max > 0):
        raise ValueError(f"depth_max must be > 0 m, got {depth_max!r}")
    if not table or not table.get("candidates"):
        return "snapshots", "no model table: nonlinear snapshots by default"
    rows = []
    for c in table["candidates"]:
        errs = [v for k, v in c["max_error_m_by_depth"].items() if float(k) <= depth_max + 1e-9]
        if errs and c.get("kind") in MODEL_PREFERENCE:
            rows.append((c["kind"], max(errs), c.get("update_ms", float("inf")), c.get("name", c["kind"])))
    if not rows:
        return "snapshots", "model table has no depth in range: nonlinear snapshots by default"
    for kind in MODEL_PREFERENCE:
        for k, err, ms, name in rows:
            if k == kind and err <= target and ms <= update_ms_max:
                return kind, (f"{name}: worst visible error {err * 1e3:.2f} mm <= {target * 1e3:.2f} mm over "
                              f"0-{depth_max * 1e3:.0f} mm, {ms:.2f} ms/update")
    k, err, ms, name = min(rows, key=lambda r: r[1])
    return k, (f"no model meets {target * 1e3:.2f} mm over 0-{depth_max * 1e3:.0f} mm; most accurate {name}: "
               f"{err * 1e3:.2f} mm, {ms:.2f} ms/update")


def load_model_table(path: str = MODEL_TABLE_PATH) -> dict | None:
    """The model table (dict) or None if the file is missing or unreadable."""
    return load_table(path)


def load_table(path: str = TABLE_PATH) -> dict | None:
    """The accuracy table (dict) or None if the file is missing or unreadable."""
    try:
        with open(path) as fh:
            return json.load(fh)
    except (OSError, ValueError):
        return None
