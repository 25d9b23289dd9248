"""Which hidden truth a twin draws: the one small config every twin node and the launcher share (a launch
file's top-level ``twin:`` section fills it). Light on purpose (pydantic only), so the launcher can validate a
launch file without importing the truth's image and kinematics stack (:mod:`flexsheet.twin.truth`)."""

from __future__ import annotations

from typing import Literal

from pydantic import BaseModel, ConfigDict, Field

__all__ = ["TruthChoice"]


class TruthChoice(BaseModel):
    """The hidden truth a twin node draws (:meth:`flexsheet.twin.truth.TwinTruth.draw`): ``realism``
    ``realistic`` (each as-built value drawn around nominal by its documented spread) or ``ideal`` (nominal
    exactly), ``truth_seed`` (int ≥ 0). Raises ``pydantic.ValidationError`` naming the field on bad values."""

    model_config = ConfigDict(extra="forbid")
    realism: Literal["realistic", "ideal"] = "realistic"
    truth_seed: int = Field(default=0, ge=0)
