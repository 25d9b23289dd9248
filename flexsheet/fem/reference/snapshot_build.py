"""The offline build of the cylinder's snapshot table (:mod:`flexsheet.fem.snapshots` is its run-time
look-up): the hyperelastic reference pushed at every snapshot azimuth and sampled on the table's surface grid
(:func:`build_table`), the table from the cache or built (:func:`load_or_build`), an earlier table it extends
(:func:`reusable_table`, :func:`reused_azimuths`), the packing that ships it (:func:`pack_table`), and the
sampling of a (half or quarter) reference model anywhere on the whole body (:func:`folded_probe`,
:func:`unfolded_sample`). Heavy: minutes to hours per azimuth.
"""

from __future__ import annotations

import logging
import math
import time
from dataclasses import replace

import numpy as np

from flexsheet.fem.material import Material
from flexsheet.fem.reference.capsule_contact import DEFAULT_CONTACT, capsule_at
from flexsheet.fem.reference.hyperelastic import HyperelasticModel
from flexsheet.fem.reference.mesh import RefSpec, reference_mesh
from flexsheet.fem.reference.path_solver import solve_path, stable_states
from flexsheet.fem.snapshots import TABLE_VERSION, SnapshotGrid, load_snapshot_table, table_key
from flexsheet.model.geometry import CYLINDER_CENTER, CYLINDER_LENGTH, CYLINDER_RADIUS

log = logging.getLogger(__name__)

__all__ = ["build_table", "load_or_build", "reusable_table", "reused_azimuths", "pack_table", "folded_probe",
           "unfolded_sample", "PREVIOUS_ANGLES_DEG"]

#: the node table's azimuths without 7.5°: the table on them is extended
#: azimuth by azimuth (:func:`reusable_table`), not solved again
PREVIOUS_ANGLES_DEG = (0.0, 5.0, 10.0, 20.0, 30.0, 40.0, 50.0, 55.0, 60.0)


def load_or_build(cache, grid: SnapshotGrid, spec: RefSpec, material: Material, finger_radius: float,
                  build: bool = True, solved=None,
                  contact: str = DEFAULT_CONTACT, reuse: dict | None = None) -> tuple[dict | None, bool,
                                                                                      float]:
    """(table or None, cache hit, seconds): the table from ``cache``
    (:class:`flexsheet.fem.cache.ArrayCache`), or built and stored when ``build`` (``solved``, ``contact``,
    ``reuse``: as :func:`build_table`)."""
    z = load_snapshot_table(cache, grid, spec, material, finger_radius, contact)
    if z is not None:
        return z, True, 0.0
    if not build:
        return None, False, 0.0
    t = time.perf_counter()
    z = build_table(grid, spec, material, finger_radius, solved=solved, contact=contact, reuse=reuse)
    cache.save("snapshots", table_key(grid, spec, material.nu, finger_radius, contact, material.Jm), z)
    return z, False, time.perf_counter() - t


def reusable_table(cache, grid: SnapshotGrid, spec: RefSpec, material: Material, finger_radius: float,
                   contact: str = DEFAULT_CONTACT,
                   previous: tuple[tuple[float, ...], ...] = (PREVIOUS_ANGLES_DEG,)) -> dict | None:
    """A cached or shipped table that :func:`build_table` can extend to ``grid`` (its ``reuse``): the table of
    the same mesh spec, material, finger radius (m) and contact law on ``grid``'s samples but an earlier
    azimuth set, each of ``previous`` tried in turn (only sets that are a proper subset of ``grid``'s
    azimuths); None when none is there. Its cache key (:func:`flexsheet.fem.snapshots.table_key`) is what
    vouches for the spec, material and contact."""
    for angles in previous:
        if not set(angles) < set(grid.angles_deg):
            continue
        z, hit, _ = load_or_build(cache, replace(grid, angles_deg=tuple(angles)), spec, material,
                                  finger_radius,
                                  build=False, contact=contact)
        if hit:
            return z
    return None


def pack_table(table: dict) -> tuple[dict, float]:
    """A table (:func:`build_table`) made small enough to ship in the repository: the surface fields ``side``
    and ``cap`` as float16 (half the bytes; :class:`flexsheet.fem.snapshots.SnapshotModel` reads them back as
    float32), everything else as it is. Returns (packed table, largest rounding error in m): float16 keeps 11
    significant bits, so a displacement of up to 64 mm is off by at most 2⁻¹⁶ m ≈ 0.015 mm, 2 % of the 0.7 mm
    target. Raises ``ValueError`` when a surface value does not fit float16's range (|u| ≥ 65504 m: not a
    displacement)."""
    out = dict(table)
    err = 0.0
    for k in ("side", "cap"):
        a = np.asarray(table[k], np.float32)
        if not np.all(np.abs(a) < np.finfo(np.float16).max):
            raise ValueError(f"snapshot table field {k!r} does not fit float16 (largest |u| "
                             f"{np.abs(a).max():g} m)")
        h = a.astype(np.float16)
        err = max(err, float(np.abs(h.astype(np.float32) - a).max(initial=0.0)))
        out[k] = h
    return out, err


def _surface_samples(th: np.ndarray, ys: np.ndarray, rh: np.ndarray, R: float, L: float, c: np.ndarray):
    """The table's sample points on the pushed half (|θ| < 90°): ``free`` (T,) bool, the side points
    (free θ × y) and the end-cap points (free θ × ρ), (N, 3) m."""
    free = np.abs(th) < math.pi / 2
    T, Y = np.meshgrid(th[free], ys, indexing="ij")
    side_pts = np.column_stack([c[0] + R * np.cos(T.ravel()), c[1] + Y.ravel(), c[2] + R * np.sin(T.ravel())])
    T2, P2 = np.meshgrid(th[free], rh, indexing="ij")
    cap_pts = np.column_stack([c[0] + P2.ravel() * np.cos(T2.ravel()), np.full(T2.size, c[1] + L / 2),
                               c[2] + P2.ravel() * np.sin(T2.ravel())])
    return free, side_pts, cap_pts


def _solve_azimuth(ang: float, spec: RefSpec, material: Material, finger_radius: float, grid: SnapshotGrid,
                   depths: np.ndarray, solved, contact: str):
    """The reference model at azimuth ``ang`` deg and its states at ``depths[1:]`` (``solved``'s, else solved
    here: the loading path and, frictionless, its stable branch)."""
    s = spec if ang == 0.0 else replace(spec, half_z=False)
    mesh = reference_mesh(s, ang)
    model = HyperelasticModel(mesh, material, sym_y=True, sym_z=s.half_z)
    law = f"Gent Jm {material.Jm:g}" if material.gent else "neo-Hookean"
    log.info(f"fem: snapshots at {ang:g} deg: {model.n} DOF P2 {law}, {len(depths) - 1} depths ...")
    states = solved(ang, model, depths[1:]) if solved is not None else None
    if states is None:
        states = solve_path(model, math.radians(ang), depths[1:], finger_radius, step=grid.depth_step,
                            contact=contact)
        if contact == "frictionless":       # the stable branch where the push is bistable
            a = math.radians(ang)

            def caps(d, a=a, m=mesh):
                return capsule_at(a, d, finger_radius, m.radius, m.center)

            states, _, _ = stable_states(model, caps, states, step=grid.depth_step)
    return model, states


def _store_states(t: dict, i: int, model, states, free, side_pts, cap_pts, ny: int, nr: int) -> None:
    """Azimuth ``i``'s states sampled into the table's arrays ``t`` (depth index 1 on)."""
    Ps = folded_probe(model, side_pts)
    Pc = folded_probe(model, cap_pts)
    for j, st in enumerate(states, start=1):
        us = unfolded_sample(Ps, st.u, side_pts, model)
        uc = unfolded_sample(Pc, st.u, cap_pts, model)
        t["side"][i, j][free] = us.reshape(int(free.sum()), ny, 3)
        t["cap"][i, j][free] = uc.reshape(int(free.sum()), nr, 3)
        t["force"][i, j], t["max_strain"][i, j], t["inverted"][i, j] = st.force, st.max_strain, st.inverted
        t["min_detF"][i, j], t["newton"][i, j] = st.min_detF, st.iterations


def _copy_reused(t: dict, i: int, reuse: dict, k: int) -> None:
    """Azimuth ``i`` of the table's arrays ``t`` copied from azimuth ``k`` of the table ``reuse``."""
    t["side"][i], t["cap"][i] = np.asarray(reuse["side"][k], np.float32), np.asarray(reuse["cap"][k],
                                                                                     np.float32)
    t["force"][i], t["max_strain"][i], t["inverted"][i] = (reuse["force"][k], reuse["max_strain"][k],
                                                           reuse["inverted"][k])
    t["min_detF"][i], t["newton"][i], t["seconds"][i] = (reuse["min_detF"][k], reuse["newton"][k],
                                                         reuse["seconds"][k])
    t["reused"][i] = True


def build_table(grid: SnapshotGrid, spec: RefSpec, material: Material, finger_radius: float,
                progress=None, solved=None, contact: str = DEFAULT_CONTACT,
                reuse: dict | None = None) -> dict[str, np.ndarray]:
    """Run the nonlinear reference at every snapshot azimuth and sample the surface; returns the table arrays
    (see :class:`flexsheet.fem.snapshots.SnapshotModel`). Heavy (minutes per azimuth on a small machine):
    cache the result (:class:`flexsheet.fem.cache.ArrayCache`). ``spec.half_z`` is used for the azimuth-0
    snapshot only. ``solved``: optional callable (azimuth deg, model, depths m) -> list of :class:`PathState`
    (or None to solve here: the loading path and, frictionless, its stable branch,
    :func:`flexsheet.fem.reference.path_solver.stable_states`), e.g. the experiment's cached stable paths on
    the same mesh, so nothing is solved twice. ``contact``: the finger's contact law
    (:func:`flexsheet.fem.reference.path_solver.solve_path_capsule`). ``reuse``: optional table of the
    **same** mesh spec, material, finger and contact law holding some of ``grid``'s azimuths (e.g. the shipped
    table before azimuths were added, :func:`reusable_table`): those azimuths are copied from it, not solved
    (its surface fields as stored: float16 in a shipped table, ≤ 0.015 mm). The caller vouches for the spec,
    material, finger and contact (its cache key); its samples (depths, θ, y, ρ, E, version) are checked here:
    ``ValueError`` when they differ. The result's ``reused`` (A,) bool marks the copied azimuths."""
    R, L, c = CYLINDER_RADIUS, CYLINDER_LENGTH, CYLINDER_CENTER
    depths = grid.depths()
    th, ys, rh = grid.thetas(), grid.ys(L / 2), grid.rhos(R)
    na, nd = len(grid.angles_deg), len(depths)
    t = {"side": np.zeros((na, nd, len(th), len(ys), 3), np.float32),
         "cap": np.zeros((na, nd, len(th), len(rh), 3), np.float32), "force": np.zeros((na, nd)),
         "max_strain": np.zeros((na, nd)), "inverted": np.zeros((na, nd), np.int64),
         "min_detF": np.ones((na, nd)),
         "newton": np.zeros((na, nd), np.int64), "seconds": np.zeros(na), "reused": np.zeros(na, bool)}
    free, side_pts, cap_pts = _surface_samples(th, ys, rh, R, L, c)
    src = _reuse_index(reuse, grid, depths, th, ys, rh, material) if reuse is not None else {}
    for i, ang in enumerate(grid.angles_deg):
        if ang in src:
            _copy_reused(t, i, reuse, src[ang])
            log.info(f"fem: snapshots at {ang:g} deg taken from the table being extended (not solved again)")
            continue
        t0 = time.perf_counter()
        model, states = _solve_azimuth(ang, spec, material, finger_radius, grid, depths, solved, contact)
        _store_states(t, i, model, states, free, side_pts, cap_pts, len(ys), len(rh))
        t["seconds"][i] = time.perf_counter() - t0
        if progress:
            progress(i, ang, states, model)
    return {"version": np.array(TABLE_VERSION), "E": np.array(material.E),
            "angles": np.radians(np.asarray(grid.angles_deg, float)),
            "depths": depths, "theta": th, "y": ys, "rho": rh, "side": t["side"], "cap": t["cap"],
            "force": t["force"],
            "max_strain": t["max_strain"], "inverted": t["inverted"], "min_detF": t["min_detF"],
            "newton": t["newton"],
            "seconds": t["seconds"], "radius": np.array(R), "length": np.array(L),
            "center": np.asarray(c, float),
            "reused": t["reused"]}


def reused_azimuths(table: dict) -> set[float]:
    """The azimuths (deg, rounded to 10⁻⁶) that :func:`build_table` copied from the table it extended (its
    ``reused`` flags); empty for a table built whole or before the flags existed."""
    if "reused" not in table:
        return set()
    return {round(math.degrees(float(a)), 6) for a, r in
            zip(np.asarray(table["angles"]), np.asarray(table["reused"], bool), strict=True) if r}


def _reuse_index(reuse: dict, grid: SnapshotGrid, depths, th, ys, rh, material: Material) -> dict[float, int]:
    """{azimuth deg of ``grid`` → its index in ``reuse``} for the azimuths ``reuse`` holds; ``ValueError``
    when ``reuse`` is sampled otherwise (version, E, depths, θ, y, ρ) than :func:`build_table` would
    sample."""
    if str(reuse.get("version", "")) != TABLE_VERSION:
        raise ValueError(f"reuse: snapshot table version {reuse.get('version')!r} != {TABLE_VERSION!r}")
    if float(reuse["E"]) != material.E:
        raise ValueError(f"reuse: table E {float(reuse['E'])!r} Pa != material E {material.E!r} Pa")
    for name, mine in (("depths", depths), ("theta", th), ("y", ys), ("rho", rh)):
        theirs = np.asarray(reuse[name], float)
        if theirs.shape != mine.shape or not np.allclose(theirs, mine, rtol=0.0, atol=1e-12):
            raise ValueError(f"reuse: the table's {name} samples differ from this grid's ({theirs.shape} vs "
                             f"{mine.shape})")
    have = np.degrees(np.asarray(reuse["angles"], float))
    out = {}
    for ang in grid.angles_deg:
        k = np.flatnonzero(np.abs(have - ang) < 1e-9)
        if k.size:
            out[ang] = int(k[0])
    return out


def folded_probe(model: HyperelasticModel, x: np.ndarray):
    """Probe matrix (k, P) csr of ``model``'s P2 field at points ``x`` (k, 3) m anywhere on the whole body,
    the points folded into the modelled part (y ≥ y_O; z ≥ z_O for a quarter model); see
    :func:`unfolded_sample`."""
    c = model.mesh.center
    xf = x.copy()
    xf[:, 1] = c[1] + np.abs(xf[:, 1] - c[1])
    if model.sym_z:
        xf[:, 2] = c[2] + np.abs(xf[:, 2] - c[2])
    return model.probe_matrix(xf)


def unfolded_sample(P, u: np.ndarray, x: np.ndarray, model: HyperelasticModel) -> np.ndarray:
    """Displacements (k, 3) m at points ``x`` (k, 3) m from ``model``'s DOF-point displacements ``u`` (P, 3) m
    via the probe matrix ``P`` of :func:`folded_probe`, unfolding the mirror images (component signs)."""
    v = np.asarray(P @ u)
    c = model.mesh.center
    v[:, 1] *= np.where(x[:, 1] < c[1], -1.0, 1.0)
    if model.sym_z:
        v[:, 2] *= np.where(x[:, 2] < c[2], -1.0, 1.0)
    return v
