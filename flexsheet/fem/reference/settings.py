"""What a run of the cylinder's reference against the real-time model computes
(:mod:`flexsheet.experiments.fem`, and the node table's build, :mod:`flexsheet.fem.reference.node_table`): the
finger, the accuracy target, the Newton budget per load step, the convergence meshes, the snapshot grid and
the studies' meshes (:class:`Settings`, :func:`settings_for`), and the reference's default material."""

from __future__ import annotations

from dataclasses import dataclass, field, replace

from flexsheet.fem.choose import DEFAULT_SPEC
from flexsheet.fem.material import Material
from flexsheet.fem.mesh import MeshSpec
from flexsheet.fem.reference.capsule_contact import DEFAULT_CONTACT, PENALTY_SCALE
from flexsheet.fem.reference.mesh import RefSpec
from flexsheet.fem.snapshots import DEFAULT_GRID, DEFAULT_REF_SPEC, SnapshotGrid
from flexsheet.model.scenes import paper_scene

FINGER_R = 0.008
FULL_LEVELS = (0.008, 0.006, 0.0045, 0.0034, 0.0025)   #: h_fine (m) of the full run's meshes, coarse → fine
#: the full run's snapshot mesh, its next-to-finest level (the studies of docs/fem.md "Reference studies"; the
#: node's own table is on :data:`flexsheet.fem.snapshots.DEFAULT_REF_SPEC`)
STUDY_SPEC = RefSpec(0.012, 0.0034, 0.018, half_z=True, path_depth=0.055, cut=True)
TARGET = 0.0007
PENALTY_TOL_MM = 0.1    #: the default penalty must lie this close (visible surface) to a 10× stiffer one
#: the fold study's tip-refined sequence (h_fine, tip_h) m: the push tube and, within TIP_RADIUS of the push
#: point, the material that ends up stretched over the fingertip, refined together (docs/fem.md, fold study)
TIP_LEVELS = ((0.0045, 0.0016), (0.0034, 0.0012), (0.0025, 0.0009))
TIP_RADIUS = 0.005
#: a finer tip alone on the middle tip level's tube (does the apex still move the surface?)
TIP_CHECK = 0.0008
NEWTON_ITERS = 60       #: per load step; a snap-through step (a crease forming beside the finger) needs ~25


@dataclass
class Settings:
    """What one run computes: convergence meshes (coarse → fine, azimuth 0), the snapshot grid and mesh,
    held-out azimuths (deg) checked against their own reference solves, the linear model's mesh (its surface
    vertices are the rendered vertices), the updates timed per configuration."""

    levels: list = field(default_factory=list)
    depth_step: float = 0.0025
    fine_step: float = 0.00125
    grid: SnapshotGrid = DEFAULT_GRID
    snap_spec: RefSpec = DEFAULT_REF_SPEC
    holdout_deg: tuple = ()
    linear_spec: MeshSpec = DEFAULT_SPEC
    n_time: int = 300
    quick: bool = False
    contact: str = DEFAULT_CONTACT
    penalty_level: int = 1
    penalty_scales: tuple = (1e3, 1e4, PENALTY_SCALE, 10 * PENALTY_SCALE)
    skin_sizes: tuple = (0.0025, 0.0018)
    half_levels: tuple = (0.006, 0.0045, 0.0034)
    tip_levels: tuple = TIP_LEVELS
    tip_check: float = TIP_CHECK


def settings_for(quick: bool) -> Settings:
    """The ``--quick`` or the full settings. Every mesh is refined along the whole push path (a tube of radius
    18 mm from the contact point to 55 mm deep, graded to ``h`` over a further 18 mm), the refinement ratio
    between levels ≈ 1.33. The snapshot table is the solution on ``snap_spec`` every ``grid.depth_step``
    (full: :data:`STUDY_SPEC`, the next-to-finest level; quick: the finest); it is judged against the finest
    level at every ``fine_step``."""
    if quick:
        lv = [RefSpec(0.016, hf, 0.018, True, 0.055) for hf in (0.012, 0.009)]
        return Settings(levels=lv, depth_step=0.005, fine_step=0.005,
                        grid=SnapshotGrid((0.0,), 0.05, 0.01, 1.0, 0.001, 0.002), snap_spec=lv[-1],
                        holdout_deg=(),
                        linear_spec=MeshSpec(0.016, 0.006, 0.012, 0.0), n_time=50, quick=True,
                        penalty_level=0,
                        penalty_scales=(PENALTY_SCALE, 10 * PENALTY_SCALE), skin_sizes=(0.005,),
                        half_levels=(0.012,), tip_levels=((0.012, 0.005), (0.009, 0.004)), tip_check=0.0)
    lv = [replace(STUDY_SPEC, h_fine=hf) for hf in FULL_LEVELS]
    grid = SnapshotGrid((0.0, 10.0, 20.0), 0.05, 0.005, DEFAULT_GRID.dtheta_deg, DEFAULT_GRID.dy,
                        DEFAULT_GRID.drho)
    # the snapshots on the study's mesh (STUDY_SPEC, the next-to-finest level), judged against the finest at
    # azimuth 0; azimuth 5 held out between snapshots at the node
    # table's 10 deg spacing, against its own solve on that mesh
    return Settings(levels=lv, depth_step=0.0025, fine_step=0.0025, grid=grid, snap_spec=STUDY_SPEC,
                    holdout_deg=(5.0,),
                    linear_spec=MeshSpec(0.012, 0.004, 0.012, 60.0), n_time=1000)


#: the reference's default material: the default scene's (the paper's cylinder, a Gent solid;
#: ``--Jm inf`` is the neo-Hookean solid the earlier studies ran)
DEFAULT_MATERIAL = Material.of_scene(paper_scene().material)


def law_name(mat: Material) -> str:
    """The reference's hyperelastic law of ``mat`` in words: "neo-Hookean" or "Gent (Jm …)"."""
    return f"Gent (Jm {mat.Jm:g})" if mat.gent else "neo-Hookean"
