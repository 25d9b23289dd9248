"""The organ scene's surface: a kidney-like closed soft body, generated procedurally (pure: numpy + trimesh).

``launch/scenes/kidney.obj`` is this module's output, shipped in the repository (≈ 150 kB) so that no run
depends on the generator; ``python -m flexsheet.model.organ_mesh launch/scenes/kidney.obj`` writes it again,
identically (tests/unit/model/test_organ_mesh.py checks that the shipped file is what this code makes).

Construction (organ frame: +x the anterior face, toward the user; +y the long axis; +z the lateral border):

1. an icosphere (``subdivisions`` 4: 2562 vertices, 5120 triangles) scaled to the ellipsoid of semi-axes
   ``SEMI_AXES`` = (30, 60, 36) mm — a kidney's proportions (adult human ≈ 110 × 60 × 35 mm, Standring,
   *Gray's Anatomy* 41st ed., ch. 74), thickened to 60 mm so that the paper's 50 mm push stays inside the
body; 2. bent into a bean: the poles drop toward −z by ``BEND`` (z −= BEND·(y/a_y)²); 3. the hilum: a smooth
dent (Gaussian, depth ``HILUM_DEPTH``) in the middle of the medial (−z) border; 4. lobulation: a few low-order
surface ripples (amplitude ≤ 0.8 mm, fixed seed), as on a fetal-lobulated kidney; 5. Taubin smoothing (λ =
0.5, ν = −0.53, 10 passes; no shrinkage), then translated so that the ray from the origin along +x leaves the
surface at x = ``FRONT`` (the scene's pose puts that point on the sheet).

The result is watertight, consistently wound with outward normals and non-convex (the hilum). Coordinates are
written in metres with 5 decimals (10 µm), far below the FEM's and the renderer's resolution.
"""

from __future__ import annotations

import argparse
import sys

import numpy as np

__all__ = ["kidney_mesh", "write_obj", "SEMI_AXES", "FRONT", "main"]

SEMI_AXES = (0.030, 0.060, 0.036)  #: ellipsoid semi-axes before bending (x thickness, y length, z width), m
BEND = 0.012                       #: pole drop toward −z, m
HILUM_DEPTH = 0.010                #: hilum dent depth, m
FRONT = 0.030                      #: the ray from the origin along +x leaves the surface at x = FRONT, m
DIGITS = 5                         #: decimals of the OBJ coordinates (m): 10 µm


def kidney_mesh(subdivisions: int = 4, seed: int = 7):
    """The kidney-like closed surface (module doc) as a ``trimesh.Trimesh`` in the organ frame, m.

    ``subdivisions``: icosphere level (4 → 5120 triangles); ``seed``: the lobulation ripples. Deterministic.
    Raises ``ValueError`` for ``subdivisions`` outside 1..6."""
    import trimesh

    if not 1 <= int(subdivisions) <= 6:
        raise ValueError(f"subdivisions must be in 1..6, got {subdivisions!r}")
    ico = trimesh.creation.icosphere(subdivisions=int(subdivisions), radius=1.0)
    u = np.asarray(ico.vertices, dtype=float)                     # unit sphere directions
    ax, ay, az = SEMI_AXES
    v = u * np.array([ax, ay, az])
    # 2. bean: the poles drop toward -z (medial side concave)
    v[:, 2] -= BEND * (v[:, 1] / ay) ** 2
    # 3. hilum: a dent pushing the middle of the medial border (-z) inward (+z)
    w = (np.exp(-0.5 * ((v[:, 1] / 0.016) ** 2 + (v[:, 0] / 0.016) ** 2)) * (u[:, 2] < 0)
         * np.clip(-u[:, 2], 0, 1))
    v[:, 2] += HILUM_DEPTH * w
    # 4. lobulation: low-order ripples along the outward direction of the unit sphere
    rng = np.random.default_rng(seed)
    ripple = np.zeros(len(u))
    for _ in range(5):
        k = rng.normal(size=3)
        k *= rng.uniform(3.0, 5.0) / np.linalg.norm(k)
        ripple += rng.uniform(0.3e-3, 0.8e-3) * np.sin(u @ k + rng.uniform(0, 2 * np.pi))
    n = u / np.array([ax, ay, az])                                # ellipsoid normal direction (unnormalised)
    v += ripple[:, None] * n / np.linalg.norm(n, axis=1, keepdims=True)
    mesh = trimesh.Trimesh(v, ico.faces.copy(), process=False)
    trimesh.smoothing.filter_taubin(mesh, lamb=0.5, nu=-0.53, iterations=10)
    # 5. put the front point (ray from the origin along +x) at x = FRONT
    loc, _, _ = mesh.ray.intersects_location([[0.0, 0.0, 0.0]], [[1.0, 0.0, 0.0]])
    mesh.apply_translation([FRONT - float(loc[:, 0].max()), 0.0, 0.0])
    mesh.fix_normals()
    return mesh


def write_obj(path: str, vertices, faces, header: str = "") -> None:
    """Write a triangle mesh as a minimal Wavefront OBJ: ``vertices`` (N, 3) m with :data:`DIGITS` decimals,
    ``faces`` (M, 3) 0-based (written 1-based), comment lines from ``header``."""
    v = np.asarray(vertices, dtype=float)
    f = np.asarray(faces, dtype=np.int64)
    lines = [f"# {h}" for h in header.splitlines()]
    lines += [f"v {x:.{DIGITS}f} {y:.{DIGITS}f} {z:.{DIGITS}f}" for x, y, z in v]
    lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in f]
    with open(path, "w", encoding="ascii") as fh:
        fh.write("\n".join(lines) + "\n")


def main(argv: list[str] | None = None) -> int:
    """``python -m flexsheet.model.organ_mesh OUT.obj``: write the kidney-like organ surface (module doc)."""
    ap = argparse.ArgumentParser(prog="python -m flexsheet.model.organ_mesh",
                                 description=__doc__.split("\n")[0],
                                 epilog="example: python -m flexsheet.model.organ_mesh "
                                        "launch/scenes/kidney.obj")
    ap.add_argument("out", help="OBJ file to write")
    ap.add_argument("--subdivisions", type=int, default=4, help="icosphere level (default 4: 5120 triangles)")
    ap.add_argument("--seed", type=int, default=7, help="lobulation seed (default 7)")
    a = ap.parse_args(argv)
    m = kidney_mesh(a.subdivisions, a.seed)
    ext = m.bounds[1] - m.bounds[0]
    write_obj(a.out, m.vertices, m.faces,
              header=f"kidney-like organ surface, m, display-frame axes (x toward the user)\n"
                     f"generated by: python -m flexsheet.model.organ_mesh (subdivisions {a.subdivisions}, "
                     f"seed {a.seed})")
    print(f"{a.out}: {len(m.vertices)} vertices, {len(m.faces)} triangles, {ext[0] * 1e3:.1f} x "
          f"{ext[1] * 1e3:.1f} x {ext[2] * 1e3:.1f} mm, volume {m.volume * 1e6:.1f} cm^3, watertight "
          f"{m.is_watertight}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
