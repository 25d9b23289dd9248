"""Common pieces of the wire contract: the header, the strict message base and typed numpy array fields.

Every message is a frozen, strict pydantic v2 model (``frozen=True, extra="forbid", strict=True``) that
carries a :class:`Header` and two class constants, ``SCHEMA`` (a stable name such as
``"flexsheet/Fingertip"``) and ``VERSION`` (an integer bumped on any incompatible change). numpy arrays are
declared with :func:`ndarray` and travel as raw buffers (see :mod:`flexsheet.runtime.codec`), never as lists.

Units are SI (m, rad, s, N) everywhere; frames are named in ``frame_id`` and in field docs.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Annotated, Any, ClassVar

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, PlainSerializer, PlainValidator, WithJsonSchema

__all__ = ["Header", "Message", "ndarray", "check_finite", "ArraySpec", "array_spec"]

#: frame name of the world frame: origin at the centre of the sheet in its home pose (the paper's
#: imaginary screen), +x toward the user (screen normal
#: n_o), +y to the user's right (the user faces −x), +z up.
DISPLAY_FRAME = "display"


class Header(BaseModel):
    """Header carried by every message.

    Fields: ``stamp`` (float, s, the sender's clock, ``time.time()`` epoch seconds), ``frame_id`` (name of
    the frame the message's geometry is expressed in, e.g. ``"display"``), ``seq`` (int ≥ 0, per-publisher
    sequence number, incremented by one for each message; gaps mean drops).
    """

    model_config = ConfigDict(frozen=True, extra="forbid", strict=True, allow_inf_nan=False)

    stamp: float = Field(description="time the data was taken, s (sender's clock, epoch seconds)")
    frame_id: str = Field(default="display", description="frame of the message's geometry")
    seq: int = Field(default=0, ge=0, description="per-publisher sequence number")


#: arrays up to this many elements are checked for finiteness as a Python float sum (faster than numpy's
#: ufuncs on a few elements)
_SMALL_ARRAY = 64


def _all_finite(value: np.ndarray) -> bool:
    """True if every element of a float array is finite. Its sum is finite only if every element is (a NaN or
    an inf propagates); a sum that overflows is settled element by element."""
    if value.size <= _SMALL_ARRAY:
        total = sum(value.ravel().tolist())
    else:
        with np.errstate(over="ignore", invalid="ignore"):   # an overflow or inf - inf: settled below
            total = np.add.reduce(value, axis=None)
    return math.isfinite(total) or bool(np.isfinite(value).all())


def _array_validator(dtype: str | None, shape: tuple[int | None, ...] | None):
    want_dtype = np.dtype(dtype) if dtype is not None else None
    ndim = len(shape) if shape is not None else None
    fixed = [(i, n) for i, n in enumerate(shape or ()) if n is not None]
    exact = tuple(shape) if shape is not None and len(fixed) == ndim else None   # every dimension fixed
    must_be_finite = want_dtype is None or want_dtype.kind == "f"
    ndarray_t = np.ndarray

    def validate(value: Any) -> np.ndarray:
        if type(value) is not ndarray_t and not isinstance(value, ndarray_t):
            raise ValueError(f"expected a numpy.ndarray, got {type(value).__name__}")
        vdtype = value.dtype
        if want_dtype is not None and vdtype is not want_dtype and vdtype != want_dtype:
            raise ValueError(f"expected dtype {want_dtype}, got {vdtype}")
        if ndim is not None:
            vs = value.shape
            if (vs != exact) if exact is not None else (len(vs) != ndim or any(vs[i] != n for i, n in fixed)):
                raise ValueError(f"expected shape {_fmt(shape)}, got {vs}")
        if must_be_finite and vdtype.kind == "f" and not _all_finite(value):
            raise ValueError(f"must be finite, got {value!r:.200}")
        return value

    return validate


@dataclass(frozen=True)
class ArraySpec:
    """The declared dtype (None: any) and shape (None entries: free; None: any) of an :func:`ndarray`
    field."""

    dtype: str | None
    shape: tuple[int | None, ...] | None


def array_spec(field_info: Any) -> ArraySpec | None:
    """The :class:`ArraySpec` of a pydantic ``FieldInfo`` declared with :func:`ndarray`, else None."""
    return next((m for m in field_info.metadata if isinstance(m, ArraySpec)), None)


def _fmt(shape: tuple[int | None, ...]) -> str:
    return "(" + ", ".join("N" if s is None else str(s) for s in shape) + ")"


def ndarray(dtype: str | None, shape: tuple[int | None, ...] | None = None, description: str = ""):
    """Annotated type for a numpy array field with a fixed dtype and shape pattern.

    Parameters
    ----------
    dtype : str or None
        numpy dtype name (``"float64"``, ``"uint8"``…); ``None`` accepts any dtype.
    shape : tuple of (int or None), optional
        Expected shape; ``None`` entries are free dimensions. ``None`` accepts any shape.

    The field validates ``isinstance(ndarray)``, dtype and shape (raising ``ValueError`` with expected vs
    got), serialises to nested lists in JSON mode (used only by ``bag export``), and advertises a JSON schema
    of nested arrays of numbers. On the wire it travels as a raw buffer (:mod:`flexsheet.runtime.codec`).
    """
    depth = len(shape) if shape is not None else 1
    item: dict[str, Any] = {"type": "integer" if dtype and np.dtype(dtype).kind in "iub" else "number"}
    if dtype == "bool":
        item = {"type": "boolean"}
    schema: dict[str, Any] = item
    for _ in range(depth):
        schema = {"type": "array", "items": schema}
    schema["description"] = (f"{description} [ndarray dtype={dtype or 'any'} "
                             f"shape={_fmt(shape) if shape else 'any'}]").strip()
    return Annotated[
        np.ndarray,
        PlainValidator(_array_validator(dtype, shape)),
        PlainSerializer(lambda a: a.tolist(), when_used="json"),
        WithJsonSchema(schema),
        ArraySpec(dtype, tuple(shape) if shape is not None else None),
    ]


def check_finite(name: str, value: Any) -> None:
    """Raise ``ValueError`` naming ``name`` and ``value`` if a float or array holds NaN or inf."""
    if isinstance(value, np.ndarray):
        if value.dtype.kind == "f" and not np.all(np.isfinite(value)):
            raise ValueError(f"{name} must be finite, got {value!r}")
    elif isinstance(value, float) and not math.isfinite(value):
        raise ValueError(f"{name} must be finite, got {value!r}")


class Message(BaseModel):
    """Base of every flexsheet message: frozen, strict, no extra fields, with a :class:`Header`.

    Float fields and float arrays must be finite (``allow_inf_nan=False`` and the array validator): a NaN
    or inf is rejected with an error naming the field.

    Subclasses set ``SCHEMA`` (str) and ``VERSION`` (int). A receiver that gets another schema or version on a
    topic rejects the message with one log line and counts it in diagnostics (:mod:`flexsheet.runtime.codec`).
    """

    model_config = ConfigDict(frozen=True, extra="forbid", strict=True, arbitrary_types_allowed=True,
                              allow_inf_nan=False)

    SCHEMA: ClassVar[str] = "flexsheet/Message"
    VERSION: ClassVar[int] = 1

    header: Header
