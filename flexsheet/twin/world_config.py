"""The world twin's settings: one definition of each — name, type, default and range — that ``nodes/world``'s
``WorldParams`` and ``SheetFemParams`` are built from (:func:`flexsheet.runtime.params.config_fields`).
Pure (no transport); the ranges are pydantic
``Field`` constraints in the annotations, checked when the params are. The finger's script (segments of
:class:`flexsheet.twin.finger.FingerScript`) and the ``scene`` file are the node's own params."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Annotated

from pydantic import Field

from flexsheet.model import geometry
from flexsheet.model.sheet_table import TABLE_DEPTHS, TABLE_POSITIONS, default_cache_dir
from flexsheet.twin.head import HeadMotion, Viewer
from flexsheet.twin.truth_choice import TruthChoice

__all__ = ["SheetFemConfig", "HeadScript", "WorldConfig"]

#: the mesh of the tables the experiments build with the defaults (h_fine, h_coarse), m
_DEFAULT_MESH = (0.004, 0.008)


@dataclass(frozen=True)
class SheetFemConfig:
    """The true sheet's FEM tables (:mod:`flexsheet.twin.world`): ``stretch_step`` clamp strain between tables;
    ``prebuild`` [lo, hi]: the clamp strains whose tables are built (or loaded) before the script starts — and,
    on a simulated clock, before simulated time starts — ``[]`` for none; ``workers``: processes building them
    at once; ``h_fine``/``h_coarse`` m element sizes; ``depths`` m and ``positions`` m: the pushes each table
    solves (:class:`flexsheet.model.sheet_table.IndentTable`); ``cache_dir`` ("": the default); ``worker_nice``:
    niceness of the worker processes. Raises ``ValueError`` for a ``prebuild`` that is not [] or
    0 ≤ lo ≤ hi ≤ 0.5, and for ``depths``/``positions`` that are not finite and increasing (depths > 0)."""

    stretch_step: Annotated[float, Field(gt=0.0, le=0.1)] = 0.01
    #: the band the bridges keep the clamps in (arm ``span_band``, strain believed) and the calibration's
    #: error around it: a default run's true clamp strain stays inside it
    prebuild: list[float] = field(default_factory=lambda: [0.0, 0.12])
    workers: Annotated[int, Field(ge=1, le=8)] = 2
    h_fine: Annotated[float, Field(ge=0.002, le=0.03)] = _DEFAULT_MESH[0]
    h_coarse: Annotated[float, Field(ge=0.002, le=0.06)] = _DEFAULT_MESH[1]
    depths: list[float] = field(default_factory=lambda: list(TABLE_DEPTHS))
    positions: list[float] = field(default_factory=lambda: list(TABLE_POSITIONS))
    cache_dir: str = ""
    worker_nice: Annotated[int, Field(ge=0, le=19)] = 15

    def __post_init__(self) -> None:
        pb = list(self.prebuild)
        if pb and not (len(pb) == 2 and all(math.isfinite(float(x)) for x in pb) and 0.0 <= pb[0] <= pb[1] <= 0.5):
            raise ValueError(f"prebuild must be [] or [lo, hi] with 0 <= lo <= hi <= 0.5 (clamp strain), got {pb!r}")
        for name, lo in (("depths", 0.0), ("positions", -math.inf)):
            xs = [float(x) for x in getattr(self, name)]
            if not xs or not all(math.isfinite(x) and x > lo for x in xs) or any(b <= a for a, b in zip(xs, xs[1:], strict=False)):
                raise ValueError(f"{name} must be finite, increasing{' and > 0' if lo == 0.0 else ''} (m), "
                                 f"got {getattr(self, name)!r}")

    def prebuild_nodes(self) -> list[float]:
        """The table nodes (clamp strains, ``stretch_step`` apart) of ``prebuild``, lowest first."""
        if not self.prebuild:
            return []
        lo, hi, st = float(self.prebuild[0]), float(self.prebuild[1]), self.stretch_step
        return [round(k * st, 6) for k in range(int(round(lo / st)), int(round(hi / st)) + 1)]

    def mesh(self) -> dict:
        """The mesh kwargs of :class:`flexsheet.model.sheet_fem.SheetFEM`: ``{}`` for the default mesh, so the
        key matches tables built by the experiments with the defaults."""
        if (self.h_fine, self.h_coarse) == _DEFAULT_MESH:
            return {}
        return {"h_fine": self.h_fine, "h_coarse": self.h_coarse}

    def tables_dir(self) -> str:
        """The folder of the cached tables: ``cache_dir``, or :func:`flexsheet.model.sheet_table.default_cache_dir`."""
        return self.cache_dir or default_cache_dir()


@dataclass(frozen=True)
class HeadScript:
    """The viewer's head in the world (:class:`flexsheet.twin.head.HeadMotion`): ``still`` (no sway: the eye at
    the paper's V), ``sway`` [x, y, z] m: the largest excursion of the eye; ``lean_in`` [start s, depth m, hold
    s] in script time, [] for none (default: 0.24 m toward the sheet from 54 s, held 2.5 s, while the
    stroke-and-push tilts the sheet toward the viewer: far enough for the head's keep-out to reach the sheet's
    path); ``occlusions`` [[start s, duration s], ...]: the glasses' markers hidden (default 1 s at 49 s).
    Raises ``ValueError`` on a malformed lean-in or span."""

    still: bool = False
    sway: list[float] = field(default_factory=lambda: [0.05, 0.05, 0.03])
    lean_in: list[float] = field(default_factory=lambda: [54.0, 0.24, 2.5])
    occlusions: list[list[float]] = field(default_factory=lambda: [[49.0, 1.0]])

    def __post_init__(self) -> None:
        if len(self.sway) != 3 or any(not (0.0 <= v <= 0.2) for v in self.sway):
            raise ValueError(f"head.sway must be [x, y, z] in [0, 0.2] m, got {self.sway!r}")
        if self.lean_in and (len(self.lean_in) != 3 or any(not v >= 0.0 for v in self.lean_in)
                             or self.lean_in[1] > 0.35):
            raise ValueError(f"head.lean_in must be [] or [start s, depth m <= 0.35, hold s], got {self.lean_in!r}")
        try:                                 # the rest (the occlusion spans) is HeadMotion's own check
            self.motion(Viewer.draw(0, "ideal"), 0)
        except ValueError as exc:
            raise ValueError(f"head.{exc}") from None

    def motion(self, viewer: Viewer, seed: int) -> HeadMotion:
        """The :class:`~flexsheet.twin.head.HeadMotion` this script plays for ``viewer`` and truth ``seed``."""
        return HeadMotion(viewer, seed=seed, sway=tuple(self.sway), still=self.still,
                          lean_in=tuple(self.lean_in) if self.lean_in else None,
                          occlusions=tuple(tuple(o) for o in self.occlusions))


@dataclass(frozen=True)
class WorldConfig:
    """The world twin's rates, truth and start (SI units): ``rate_hz`` of the finger, ``sheet_rate_hz`` of the
    sheet, ``membrane_grid`` G (G×G deflection samples), ``twin`` the hidden truth, ``sheet_size`` m,
    ``start_delay`` s after the nodes of ``start_after`` (or ``start_timeout`` s), ``loop``,
    ``progress_period`` s, ``head`` the viewer's head (:class:`HeadScript`)."""

    rate_hz: Annotated[float, Field(gt=0.0, le=2000.0)] = 100.0
    sheet_rate_hz: Annotated[float, Field(gt=0.0, le=1000.0)] = 50.0
    membrane_grid: Annotated[int, Field(ge=2, le=128)] = 24
    twin: TruthChoice = field(default_factory=TruthChoice)
    sheet_size: Annotated[float, Field(gt=0.0)] = geometry.SHEET_SIZE
    start_delay: Annotated[float, Field(ge=0.0)] = 3.0
    start_after: list[str] = field(default_factory=list)
    start_timeout: Annotated[float, Field(gt=0.0)] = 60.0
    loop: bool = False
    progress_period: Annotated[float, Field(gt=0.0)] = 2.0
    head: HeadScript = field(default_factory=HeadScript)
