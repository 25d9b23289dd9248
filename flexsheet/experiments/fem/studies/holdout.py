"""The held-out azimuth study (``--holdout-study``, ``holdout_study.json``, :func:`holdout_study`): the
snapshots between azimuths alone, on a table of the azimuths around each held-out one
(:func:`holdout_grid`)."""

from __future__ import annotations

import logging
from dataclasses import replace

from flexsheet.experiments.fem.candidates import snapshot_source, validation_set
from flexsheet.fem.cache import ArrayCache
from flexsheet.fem.material import Material
from flexsheet.fem.realtime import RealtimeModel
from flexsheet.fem.reference.paths import snapshot_table
from flexsheet.fem.reference.settings import FINGER_R, TARGET, Settings
from flexsheet.fem.visible_error import errors

log = logging.getLogger(__name__)


def holdout_grid(st: Settings) -> Settings:
    """``st`` with its snapshot azimuths cut to the grid's first azimuth (0, judged too) and the two around
    each held-out one (full mode: 0 and 10 for 5), the ones the table's blend reads. ``ValueError`` when there
    is no held-out azimuth or one is not inside the grid."""
    if not st.holdout_deg:
        raise ValueError("these settings hold no azimuth out (the quick settings): nothing to study")
    g = sorted(st.grid.angles_deg)
    keep = {g[0]}
    for a in st.holdout_deg:
        lo, hi = [x for x in g if x <= a], [x for x in g if x >= a]
        if not lo or not hi:
            raise ValueError(f"held-out azimuth {a:g} deg is outside the snapshot grid {g} deg")
        keep |= {lo[-1], hi[0]}
    return replace(st, grid=replace(st.grid, angles_deg=tuple(sorted(keep))))


def holdout_study(st: Settings, mat: Material, cache: ArrayCache, rm: RealtimeModel, fine: dict) -> dict:
    """The nonlinear snapshots between azimuths, alone (``--holdout-study``): a table on the grid azimuths
    around each held-out azimuth (:func:`holdout_grid`; the snapshot mesh's cut half model away from 0, every
    ``grid.depth_step``), judged at the held-out azimuth against its own solve on that mesh, and at azimuth 0
    against the finest mesh, at every ``fine_step`` 0–50 mm, on the visible surface (:func:`errors`). The same
    check as the full run's failure map at the held-out azimuth, without the studies that need the other
    solves. Returns per azimuth: depths (mm), worst visible error (mm) per depth, its maximum and the first
    depth over the 0.7 mm target; ``rm``'s snapshot table is left as it was."""
    hs = holdout_grid(st)
    keep = rm.snapshots
    try:
        solved, _ = snapshot_source(hs, mat, cache, rm, fine)
        table, hit, sec = snapshot_table(hs, mat, cache, solved)
        rm.attach_snapshots(table)
        cases = validation_set(hs, mat, cache, rm, fine)
        err = errors(rm, cases, "snapshots")
    finally:
        rm.snapshots = keep
    rows = []
    for a in sorted({c["angle_deg"] for c in cases}):
        pairs = [(c["depth"] * 1e3, e * 1e3) for c, e in zip(cases, err, strict=True) if c["angle_deg"] == a]
        bad = [d for d, e in pairs if e > TARGET * 1e3]
        rows.append({"azimuth_deg": a, "held_out": a in hs.holdout_deg,
                     "against": "its own solve on the snapshot mesh (cut half model)" if a in hs.holdout_deg
                     else f"the finest convergence mesh (h_fine {st.levels[-1].h_fine * 1e3:g} mm)",
                     "depths_mm": [d for d, _ in pairs], "error_mm": [e for _, e in pairs],
                     "max_error_mm": max(e for _, e in pairs),
                     "breaks_at_depth_mm": min(bad) if bad else None})
        log.info(f"holdout study: azimuth {a:g} deg: worst visible error {rows[-1]['max_error_mm']:.2f} mm"
                 + (f", over the target from {min(bad):g} mm" if bad else ", within the target"))
    return {"snapshot_azimuths_deg": list(hs.grid.angles_deg), "held_out_deg": list(hs.holdout_deg),
            "snapshot_depth_step_mm": hs.grid.depth_step * 1e3, "snapshot_mesh": hs.snap_spec.__dict__,
            "table_build_s": sec, "table_cache_hit": hit, "target_mm": TARGET * 1e3,
            "footprint": f"left out: vertices whose deformed position (the reference's) lies within "
                         f"{(FINGER_R + 0.002) * 1e3:g} mm of the push axis (finger radius + 2 mm), hidden "
                         "by the finger",
            "azimuths": rows}
