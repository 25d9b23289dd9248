"""The twin's true sheet for any truth seed, from one shipped table family (pure: numpy).

The sheet FEM (:mod:`flexsheet.model.sheet_fem`) of a truth at clamp strain s depends on the drawn sheet
through three numbers only:

* **E·t** (Young's modulus × thickness): the increment's stiffness C ∝ E t and the pre-stress
  N⁰ = T_u·n with T_u = μ t g(ε) ∝ E t (:func:`flexsheet.model.tension.tension`); the membrane has no
  bending. So the force scales exactly by E t / (E₀ t₀) at a given deformation, and the shape does not
  change (the contact penalty alone is fixed: ≲ 10⁻⁴ relative, measured);
* **ε**, the strain the sheet takes between the jaws, s·(1 − grip slip) + pre-strain: the tension;
* **s**, the clamp strain: the span a = size·(1 + s)/2.

**Family** (:data:`A_STRAINS`, :data:`B_STRAINS`): FEM tables at the nominal E₀, t₀ of the sheet gripped at
the span of s = ε (layer A, 11 strains 0.0025–0.32) and of s = ε + :data:`SPAN_OFFSET` (layer B, 4 strains),
each at :data:`FORCE_DEPTHS` × the table's contacts (:data:`flexsheet.model.sheet_table.TABLE_POSITIONS`,
both signs by symmetry), the deflection kept at :data:`flexsheet.model.sheet_table.TABLE_DEPTHS`. Built once
and shipped in ``flexsheet/twin/sheet_tables/`` (``python -m flexsheet.twin.truth_sheet --ship``, ~1 h of one
core). The force of a truth at depth d, contact (u, v), clamp strain s:

    F = (E t / E₀ t₀) · F_A(ε; d, u, v) · [1 + (R(ε; d, u, v) − 1)·(s − ε)/SPAN_OFFSET],

F_A cubic in ε through the 4 layer-A strains around it, R = F_B/F_A linear in ε between layer B's (held beyond
them), each table's F/d cubic in d through the 4 depths around (exact for α d + c d³) and bilinear between
contacts. A slack clamp strain (s < 0) reads the sheet at s = 0 (its pre-strain only); an ε below 0.0025 reads
0.0025. The shape (deflection) is the nearest layer-A table's, mapped onto the actual span.
``tests/unit/twin/test_truth_sheet.py`` and ``python -m flexsheet.twin.truth_sheet --check`` compare it with
full FEM solves of drawn truths.

Units: m, N, Pa; strains dimensionless.
"""

from __future__ import annotations

import hashlib
import json
import logging
import os
import time

import numpy as np

from flexsheet.calibration.sheet import PRESS_POINTS
from flexsheet.manifest import MANIFEST, record
from flexsheet.model import geometry
from flexsheet.model.sheet import clamp_half_span
from flexsheet.model.sheet_fem import SheetFEM, SheetPhysics
from flexsheet.model.sheet_table import TABLE_DEPTHS, TABLE_POSITIONS, IndentTable, bracket_weights
from flexsheet.model.tension import URETHANE_E, SheetMaterial, tension
from flexsheet.twin.truth import TwinTruth

log = logging.getLogger(__name__)

__all__ = ["A_STRAINS", "B_STRAINS", "SPAN_OFFSET", "FORCE_DEPTHS", "FAMILY_DIR", "FamilyTable", "TruthSheet",
           "family_physics", "family_key", "node_path", "build_node", "load_family", "missing_nodes", "ship"]

#: layer A: the strains ε between the jaws, each at the span of clamp strain s = ε
A_STRAINS = (0.0025, 0.005, 0.01, 0.02, 0.04, 0.06, 0.08, 0.11, 0.16, 0.23, 0.32)
#: layer B: strains ε at the span of clamp strain s = ε + SPAN_OFFSET (the span's own effect on the force)
B_STRAINS = (0.01, 0.04, 0.11, 0.23)
#: clamp strain of layer B's span above its tension strain
SPAN_OFFSET = 0.03
#: depths (m) whose force each family table keeps (a superset of TABLE_DEPTHS, whose deflections it keeps)
FORCE_DEPTHS = (0.0005, 0.001, 0.002, 0.003, 0.005, 0.0075, 0.010, 0.015, 0.020, 0.025, 0.030, 0.035, 0.050)
#: the family's nominal sheet: E₀ (Pa), t₀ (m), side (m)
E0, T0, SIZE = URETHANE_E, geometry.SHEET_THICKNESS, geometry.SHEET_SIZE
#: where the family is shipped
FAMILY_DIR = os.path.join(os.path.dirname(os.path.abspath(__file__)), "sheet_tables")
#: version of the family's definition (in :func:`family_key`)
FAMILY_VERSION = 1


def family_physics(strain: float, span_strain: float) -> SheetPhysics:
    """The nominal gripped sheet (E₀, t₀, side SIZE) at the tension of ``strain`` ε held at the span of clamp
    strain ``span_strain``."""
    mat = SheetMaterial(young=E0, thickness=T0, size=SIZE)
    return SheetPhysics(half_span=clamp_half_span(span_strain, SIZE), half_width=SIZE / 2, young=E0,
                        thickness=T0,
                        tension_u=tension(strain, mat), tension_ratio=None)


def family_key() -> str:
    """12 hex digits naming everything that defines a family table but its strains (physics defaults, mesh,
    depths, contacts, version)."""
    doc = {"physics": family_physics(0.04, 0.04).key(), "force_depths": list(FORCE_DEPTHS),
           "depths": list(TABLE_DEPTHS), "positions": list(TABLE_POSITIONS), "version": FAMILY_VERSION}
    return hashlib.sha256(json.dumps(doc, sort_keys=True).encode()).hexdigest()[:12]


def node_path(layer: str, strain: float, folder: str = FAMILY_DIR) -> str:
    """The file of family table ``layer`` ("A" or "B") at ``strain``:
    ``truthsheet_<layer><ε·10⁴>-<key>.npz``."""
    return os.path.join(folder, f"truthsheet_{layer}{round(strain * 1e4):04d}-{family_key()}.npz")


def build_node(layer: str, strain: float, folder: str = FAMILY_DIR) -> str:
    """Solve family table ``layer`` at ``strain`` (9 contacts × :data:`FORCE_DEPTHS`, ~2–10 min of one core)
    and write it (x (nx,), y (ny,) m; W (3, 3, 5, nx, ny) float32 m at TABLE_DEPTHS; F (3, 3, 5) N; Fd (3, 3,
    13) N at FORCE_DEPTHS). Returns the path."""
    span = strain + (SPAN_OFFSET if layer == "B" else 0.0)
    fem = SheetFEM(family_physics(strain, span))
    P, D = np.asarray(TABLE_POSITIONS), list(FORCE_DEPTHS)
    keep = [D.index(d) for d in TABLE_DEPTHS]
    W = np.zeros((P.size, P.size, len(keep), fem.x.size, fem.y.size), np.float32)
    Fd = np.zeros((P.size, P.size, len(D)))
    t0 = time.monotonic()
    for i, pu in enumerate(P):
        for j, pv in enumerate(P):
            sols = fem.solve_indent(D, float(pu), float(pv))
            Fd[i, j] = [s.force for s in sols]
            for k, kk in enumerate(keep):
                W[i, j, k] = sols[kk].w
    path = node_path(layer, strain, folder)
    os.makedirs(folder, exist_ok=True)
    tmp = f"{path}.{os.getpid()}.tmp.npz"
    np.savez_compressed(tmp, x=fem.x, y=fem.y, W=W, F=Fd[:, :, keep], Fd=Fd, strain=strain, span_strain=span,
                        key=family_key())
    os.replace(tmp, path)
    log.info("truth sheet table %s %.4f built in %.0f s", layer, strain, time.monotonic() - t0)
    return path



def all_nodes() -> list[tuple[str, float]]:
    """Every (layer, strain) of the family."""
    return [("A", s) for s in A_STRAINS] + [("B", s) for s in B_STRAINS]


def missing_nodes(folder: str = FAMILY_DIR) -> list[tuple[str, float]]:
    """The family's (layer, strain) whose table ``folder`` lacks."""
    return [(lay, s) for lay, s in all_nodes() if not os.path.isfile(node_path(lay, s, folder))]


def ship(folder: str = FAMILY_DIR) -> list[str]:
    """Build the family's missing tables into ``folder`` (one after the other) and make its manifest list them
    alone: any other table there (another family key or strain) is deleted. Returns the paths."""
    for lay, s in missing_nodes(folder):
        build_node(lay, s, folder)
    keep = {os.path.basename(node_path(lay, s, folder)) for lay, s in all_nodes()}
    for name in os.listdir(folder):
        if (name.endswith(".npz") and name not in keep) or name == MANIFEST:
            os.remove(os.path.join(folder, name))
    out = []
    for lay, s in all_nodes():
        out.append(node_path(lay, s, folder))
        record(out[-1], "python -m flexsheet.twin.truth_sheet --ship")
    return out


# ------------------------------------------------------------------------------------------------ evaluation
def _cubic_weights(axis: np.ndarray, q: float) -> list[tuple[int, float]]:
    """(index, weight) of the cubic through the 4 nodes of ``axis`` around ``q`` (Lagrange; held at the
    ends)."""
    n = len(axis)
    if q <= axis[0] or q >= axis[-1] or n < 4:
        return bracket_weights(axis, q)
    i = int(np.searchsorted(axis, q, side="right") - 1)
    lo = min(max(i - 1, 0), n - 4)
    idx = range(lo, lo + 4)
    out = []
    for k in idx:
        w = 1.0
        for m in idx:
            if m != k:
                w *= (q - axis[m]) / (axis[k] - axis[m])
        out.append((k, w))
    return out


_D = np.asarray(FORCE_DEPTHS)
_D2 = _D ** 2


class FamilyTable:
    """One shipped family table (``path``): ``layer``, ``strain`` ε, ``span_strain``, the forces ``Fd``
    (3, 3, 13) N at :data:`FORCE_DEPTHS` × contacts; its deflections load on first use (:meth:`indent_table`).
    Raises ``ValueError`` for a table of another family key."""

    def __init__(self, path: str) -> None:
        with np.load(path) as z:
            if str(z["key"]) != family_key():
                raise ValueError(f"{path}: a table of another family ({z['key']}, want {family_key()})")
            self.strain, self.span_strain = float(z["strain"]), float(z["span_strain"])
            self.Fd = np.asarray(z["Fd"], float)
        self.path = path
        self.layer = os.path.basename(path)[len("truthsheet_")]
        self.positions = np.asarray(TABLE_POSITIONS)
        self._g = self.Fd / _D                          # F/d (3, 3, 13), N/m
        self._table = None

    def force(self, depth: float, pu: float, pv: float) -> float:
        """Force (N) at ``depth`` m (≥ 0), contact (pu, pv) m (signs by symmetry; held at the outer contacts):
        bilinear between contacts; F/d cubic in d through the 4 depths around (held below the first, linear in
        d² beyond the last)."""
        g = 0.0
        for i, wi in bracket_weights(self.positions, abs(pu)):
            for j, wj in bracket_weights(self.positions, abs(pv)):
                g = g + (wi * wj) * self._g[i, j]
        if depth > _D[-1]:
            gd = float(g[-1] + (g[-1] - g[-2]) * (depth ** 2 - _D2[-1]) / (_D2[-1] - _D2[-2]))
        else:
            gd = float(sum(w * g[k] for k, w in _cubic_weights(_D, depth)))
        return max(depth, 0.0) * gd

    def indent_table(self):
        """The table's deflections as an :class:`flexsheet.model.sheet_table.IndentTable` (loaded once)."""
        if self._table is None:
            with np.load(self.path) as z:
                self._table = IndentTable.from_arrays(family_physics(self.strain, self.span_strain),
                                                      TABLE_DEPTHS,
                                                      TABLE_POSITIONS, z["x"], z["y"], z["W"], z["F"])
        return self._table


_FAMILIES: dict[str, dict[str, list[FamilyTable]]] = {}


def load_family(folder: str = FAMILY_DIR) -> dict[str, list[FamilyTable]]:
    """The family in ``folder`` ({"A": tables by strain, "B": ...}; loaded once per process). Raises
    ``FileNotFoundError`` naming the missing tables and the command that ships them."""
    if folder not in _FAMILIES:
        missing = missing_nodes(folder)
        if missing:
            names = ", ".join(f"{lay}{s:g}" for lay, s in missing)
            raise FileNotFoundError(
                f"the true sheet's table family in {folder} lacks {len(missing)} of {len(all_nodes())} "
                "tables: build and ship them with python -m flexsheet.twin.truth_sheet --ship (minutes to "
                f"an hour of one core), then commit flexsheet/twin/sheet_tables/ (missing: {names})")
        _FAMILIES[folder] = {lay: [FamilyTable(node_path(lay, s, folder)) for s in strains]
                             for lay, strains in (("A", A_STRAINS), ("B", B_STRAINS))}
    return _FAMILIES[folder]


class TruthSheet:
    """The true sheet of one truth (``young`` Pa, ``thickness`` m, ``prestrain``, ``grip_slip``: the drawn
    values of :class:`flexsheet.twin.truth.TwinTruth`) from the family in ``folder`` (module doc)."""

    def __init__(self, young: float, thickness: float, prestrain: float, grip_slip: float,
                 folder: str = FAMILY_DIR) -> None:
        self.scale = float(young) * float(thickness) / (E0 * T0)
        self.prestrain, self.grip_slip = float(prestrain), float(grip_slip)
        fam = load_family(folder)
        self.A, self.B = fam["A"], fam["B"]
        self._a = np.array([t.strain for t in self.A])
        self._b = np.array([t.strain for t in self.B])
        self._a_of_b = [A_STRAINS.index(s) for s in B_STRAINS]

    @classmethod
    def of(cls, truth, folder: str = FAMILY_DIR) -> TruthSheet:
        """The true sheet of ``truth`` (a :class:`flexsheet.twin.truth.TwinTruth`)."""
        return cls(truth.sheet_young, truth.sheet_thickness, truth.sheet_prestrain, truth.grip_slip, folder)

    def preload(self) -> None:
        """Load every layer-A table's deflections now (~1 s) rather than at the first push near it."""
        for tab in self.A:
            tab.indent_table()

    def strain(self, stretch: float) -> float:
        """The strain ε between the jaws at clamp strain ``stretch`` (slack: 0): s·(1 − slip) + pre-strain."""
        return max(stretch, 0.0) * (1.0 - self.grip_slip) + self.prestrain

    def force(self, depth: float, push_u: float, push_v: float, stretch: float) -> float:
        """True force (N) at ``depth`` m, contact (push_u, push_v) m (sheet frame, from the centre), clamp
        strain ``stretch`` (module doc); 0 at depth ≤ 0."""
        if depth <= 0.0:
            return 0.0
        eps = self.strain(stretch)
        fa = sum(w * self.A[k].force(depth, push_u, push_v) for k, w in _cubic_weights(self._a, eps))
        r = 0.0
        for k, w in bracket_weights(self._b, eps):
            a = self.A[self._a_of_b[k]].force(depth, push_u, push_v)
            r += w * (self.B[k].force(depth, push_u, push_v) / a if a > 0.0 else 1.0)
        return self.scale * fa * (1.0 + (r - 1.0) * (max(stretch, 0.0) - eps) / SPAN_OFFSET)

    def stiffness(self, depth: float, push_u: float, push_v: float, stretch: float, h: float = 5e-4) -> float:
        """dF/d(depth), N/m: central difference over ±``h`` m (one-sided at 0), ≥ 0."""
        lo = max(depth - h, 0.0)
        up, down = self.force(depth + h, push_u, push_v, stretch), self.force(lo, push_u, push_v, stretch)
        return max((up - down) / (depth + h - lo), 0.0)

    def shape(self, depth: float, push_u: float, push_v: float, half_span: float, stretch: float):
        """The pushed shape (:class:`flexsheet.model.sheet_table.FemShape`) at the actual ``half_span`` m: the
        deflection of the layer-A table nearest the strain, with this sheet's force and stiffness. Raises
        ``ValueError`` for a contact outside the sheet."""
        from dataclasses import replace

        eps = self.strain(stretch)
        near = self.A[int(np.argmin(np.abs(self._a - eps)))].indent_table()
        sh = near.shape(depth, push_u, push_v, half_span)
        return replace(sh, force=self.force(depth, push_u, push_v, stretch),
                       stiffness=self.stiffness(depth, push_u, push_v, stretch))


# ------------------------------------------------------------------------------------------------ check
#: depths (m) of the check against the full FEM
CHECK_DEPTHS = (0.001, 0.002, 0.005, 0.008, 0.012, 0.017, 0.022, 0.027, 0.030)
#: clamp-strain bins of the check: one strain drawn in each
CHECK_BINS = ((-0.02, 0.06), (0.06, 0.14), (0.14, 0.22), (0.22, 0.30))


def check_seeds(n: int = 3) -> list[int]:
    """The truth seeds of the check: drawn from a fixed generator, not chosen."""
    return [int(x) for x in np.random.default_rng(20261127).integers(1, 100_000, n)]


def check_points(seed: int, bins=CHECK_BINS, off_grid: bool = True) -> list[tuple[float, float, float, bool]]:
    """(clamp strain, u m, v m, on a table contact) of the check for truth ``seed``: per bin a strain drawn in
    it at a press point (:data:`flexsheet.calibration.sheet.PRESS_POINTS`) drawn too; with ``off_grid`` one
    more strain and a contact drawn anywhere within |u|, |v| ≤ 72 mm (between the table's contacts)."""
    rng = np.random.default_rng([int(seed), 7])
    out = []
    for lo, hi in bins:
        u, v = PRESS_POINTS[int(rng.integers(len(PRESS_POINTS)))]
        out.append((float(rng.uniform(lo, hi)), float(u), float(v), True))
    if off_grid:
        u, v = rng.uniform(-0.072, 0.072, 2)
        out.append((float(rng.uniform(bins[0][0], bins[-1][1])), float(u), float(v), False))
    return out


def check(seeds, depths=CHECK_DEPTHS, bins=CHECK_BINS, off_grid: bool = True,
          folder: str = FAMILY_DIR) -> dict:
    """The truth sheet against full FEM solves (:class:`SheetFEM` of :meth:`SheetPhysics.from_truth`, a slack
    strain at 0) of the realistic truths of ``seeds`` at :func:`check_points` × ``depths``: a JSON-able dict
    with every point's forces (N) and relative error (%), and the largest error per seed on and off the
    table's contacts."""
    t0 = time.monotonic()
    rows, worst = [], {}
    for seed in seeds:
        truth = TwinTruth.draw(int(seed), "realistic")
        sheet = TruthSheet.of(truth, folder)
        for s, u, v, on_grid in check_points(seed, bins, off_grid):
            fem = SheetFEM(SheetPhysics.from_truth(truth, max(s, 0.0)))
            sols = fem.solve_indent(list(depths), u, v)
            for d, sol in zip(depths, sols, strict=True):
                f = sheet.force(d, u, v, s)
                err = 100.0 * (f - sol.force) / sol.force
                rows.append({"seed": int(seed), "stretch": round(s, 5), "strain": round(sheet.strain(s), 5),
                             "u": round(u, 4), "v": round(v, 4), "on_grid": on_grid, "depth": d,
                             "fem_N": round(sol.force, 6), "truth_sheet_N": round(f, 6),
                             "error_pct": round(err, 3)})
                key = f"{seed} {'on' if on_grid else 'off'}"
                worst[key] = max(worst.get(key, 0.0), abs(err))
            log.info("check seed %d strain %.3f (%.3f, %.3f): worst %.2f %%", seed, s, u, v, worst[key])
    return {"seeds": [int(s) for s in seeds], "depths_m": list(depths), "bins": [list(b) for b in bins],
            "worst_pct": {k: round(e, 3) for k, e in worst.items()}, "points": rows,
            "seconds": round(time.monotonic() - t0, 1), "loadavg": _loadavg()}


def _loadavg() -> str:
    try:
        with open("/proc/loadavg") as fh:
            return fh.read().strip()
    except OSError:
        return ""


def main(argv: list[str] | None = None) -> int:
    """``--ship``: build the family's missing tables and enter them in the manifest;
    ``--check [--json PATH]``: :func:`check` on :func:`check_seeds` (~10 min of one core)."""
    import argparse

    ap = argparse.ArgumentParser(prog="python -m flexsheet.twin.truth_sheet",
                                 epilog="example: python -m flexsheet.twin.truth_sheet --check --json "
                                        "docs/figures/twin/truth_check.json")
    ap.add_argument("--ship", action="store_true", help="build the missing family tables and ship them")
    ap.add_argument("--build", nargs="+", metavar="LAYER+STRAIN",
                    help="build these tables only (e.g. A0.04 B0.1)")
    ap.add_argument("--check", action="store_true", help="compare with full FEM solves of three drawn truths")
    ap.add_argument("--json", help="write the check here")
    a = ap.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(message)s")
    for item in a.build or []:
        if not os.path.isfile(node_path(item[0], float(item[1:]))):
            print(build_node(item[0], float(item[1:])), flush=True)
    if a.ship:
        for path in ship():
            print(path)
    if a.check:
        out = check(check_seeds())
        print(json.dumps(out["worst_pct"], indent=1))
        if a.json:
            os.makedirs(os.path.dirname(a.json) or ".", exist_ok=True)
            with open(a.json, "w") as fh:
                json.dump(out, fh, indent=1)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
