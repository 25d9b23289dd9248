"""The world twin's settings: one definition of each — name, type, default and range — that ``nodes/world``'s
``WorldParams`` is built from (:func:`flexsheet.runtime.params.config_fields`).
Pure (no transport); the ranges are pydantic
``Field`` constraints in the annotations, checked when the params are. The finger's script (segments of
:class:`flexsheet.twin.finger.FingerScript`) and the ``scene`` file are the node's own params."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Annotated

from pydantic import Field

from flexsheet.model import geometry
from flexsheet.model.truth_choice import TruthChoice
from flexsheet.twin.head import HeadMotion, Viewer

__all__ = ["HeadScript", "WorldConfig"]


@dataclass(frozen=True)
class HeadScript:
    """The viewer's head in the world (:class:`flexsheet.twin.head.HeadMotion`): ``still`` (no sway: the eye
    at the paper's V), ``sway`` [x, y, z] m: the largest excursion of the eye; ``lean_in`` [start s, depth m,
    hold s] in script time, [] for none (default: 0.24 m toward the sheet from 54 s, held 2.5 s, while the
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
            raise ValueError("head.lean_in must be [] or [start s, depth m <= 0.35, hold s], got "
                             f"{self.lean_in!r}")
        try:                                 # the rest (the occlusion spans) is HeadMotion's own check
            self.motion(Viewer.draw(0, "ideal"), 0)
        except ValueError as exc:
            raise ValueError(f"head.{exc}") from None

    def motion(self, viewer: Viewer, seed: int) -> HeadMotion:
        """The :class:`~flexsheet.twin.head.HeadMotion` this script plays for ``viewer`` and truth
        ``seed``."""
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
