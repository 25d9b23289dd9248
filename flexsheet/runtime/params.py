"""A node's ``Params`` from the pure module's config dataclass: one definition of each setting.

The algorithms keep their settings in frozen dataclasses beside the code that uses them (e.g.
:class:`flexsheet.planning.planner_config.PlannerConfig`, :class:`flexsheet.vision.tracker.TrackerConfig`,
:class:`flexsheet.twin.finger.FingerScript`), with the defaults and the range checks (``__post_init__``). A
node's launch-file parameters are a flat pydantic model (``extra="forbid"``, so a typo is an error). This
module builds those pydantic fields *from* the dataclass — same names, types and defaults — so nothing is
copied, and builds the dataclass back from a validated params object. Range checks stay in the dataclass: the
params model calls it in an ``after`` validator, so a bad value still fails before any socket opens, with the
dataclass's message naming the field.

Example::

    PlannerParams = params_model("PlannerParams", doc, config_fields(PlannerConfig, exclude=("limits",)),
                                 config_fields(MotionLimits), shape=(str, Field("cylinder")))
    cfg = build(MotionLimits, params)            # MotionLimits(v_max=params.v_max, ...)
"""

from __future__ import annotations

import dataclasses
import typing
from collections.abc import Callable, Iterable, Mapping
from typing import Any

from pydantic import BaseModel, ConfigDict, Field, create_model, model_validator
from pydantic.fields import FieldInfo

__all__ = ["config_fields", "params_model", "build"]


def config_fields(cls: type, *, exclude: Iterable[str] = (), rename: Mapping[str, str] | None = None,
                  descriptions: Mapping[str, str] | None = None) -> dict[str, tuple[Any, Any]]:
    """pydantic field definitions ``{param_name: (type, FieldInfo)}`` for the init fields of dataclass
    ``cls``.

    Types come from the dataclass annotations (resolved with :func:`typing.get_type_hints`), defaults (or
    default factories) from its fields. ``exclude``: field names left out (e.g. nested configs flattened by
    the caller); ``rename``: field name → param name (e.g. ``{"size": "sheet_size"}``); ``descriptions``:
    field name → text for the schema (else the ``description`` of a ``Field`` in the field's ``Annotated``
    type, else ``Class.field``). Constraints in the annotation (``Annotated[float, Field(gt=0.0)]``) are kept.
    A field without a default becomes a required param. Raises
    ``TypeError`` if ``cls`` is not a dataclass, ``KeyError`` for an excluded/renamed name it does not have.
    """
    if not dataclasses.is_dataclass(cls):
        raise TypeError(f"{cls!r} is not a dataclass")
    fields = {f.name: f for f in dataclasses.fields(cls) if f.init}
    rename = dict(rename or {})
    excl = set(exclude)
    for name in excl | set(rename):
        if name not in fields:
            raise KeyError(f"{cls.__name__} has no field {name!r}")
    hints = typing.get_type_hints(cls, include_extras=True)   # Annotated[..., Field(gt=0)] constraints kept
    out: dict[str, tuple[Any, Any]] = {}
    for name, f in fields.items():
        if name in excl:
            continue
        desc = ((descriptions or {}).get(name) or _annotated_description(hints[name])
                or f"{cls.__name__}.{name}")
        if f.default is not dataclasses.MISSING:
            info = Field(default=f.default, description=desc)
        elif f.default_factory is not dataclasses.MISSING:
            info = Field(default_factory=f.default_factory, description=desc)
        else:
            info = Field(description=desc)
        out[rename.get(name, name)] = (hints[name], info)
    return out


def _annotated_description(hint: Any) -> str | None:
    """The ``description`` of the last ``Field(...)`` in an ``Annotated`` type that has one, else None."""
    if typing.get_origin(hint) is not typing.Annotated:
        return None
    descs = [m.description for m in hint.__metadata__ if isinstance(m, FieldInfo) and m.description]
    return descs[-1] if descs else None


def build(cls: type, params: BaseModel, *, rename: Mapping[str, str] | None = None, **override: Any):
    """Instance of dataclass ``cls`` from the params object's attributes of the same (or ``rename``\\d) names,
    plus ``override`` (e.g. nested configs). Raises what ``cls`` raises (``ValueError`` naming the field)."""
    rename = dict(rename or {})
    kw = {f.name: getattr(params, rename.get(f.name, f.name)) for f in dataclasses.fields(cls)
          if f.init and f.name not in override}
    return cls(**kw, **override)


def params_model(name: str, doc: str, *parts: Mapping[str, tuple[Any, Any]],
                 check: Callable[[Any], Any] | None = None, methods: Mapping[str, Callable] | None = None,
                 validators: Mapping[str, Any] | None = None, module: str | None = None,
                 **extra: tuple[Any, Any]) -> type[BaseModel]:
    """A flat pydantic params model (``extra="forbid"``) named ``name`` with docstring ``doc`` from field
    definition dicts ``parts`` (see :func:`config_fields`) and node-only fields ``extra`` (``(type, Field)``).

    ``check(params)``, if given, runs after field validation (build the config there, so its range checks
    reject bad values early; its ``ValueError`` becomes a pydantic ``ValidationError``). ``methods``: extra
    methods of the model (e.g. ``planner_config``); ``validators``: name → pydantic validator
    (``field_validator("scene")(fn)``, ``model_validator(mode="after")(fn)``, as written in a class body: a
    field's own check keeps its error at that field, an ``after`` validator may fill defaults that depend on
    other fields); ``module``: the ``__module__`` to report (the caller's). Raises ``ValueError`` when two
    parts define the same param name or a validator's name is taken.
    """
    defs: dict[str, tuple[Any, Any]] = {}
    for part in (*parts, extra):
        for k, v in part.items():
            if k in defs:
                raise ValueError(f"{name}: param {k!r} defined twice")
            defs[k] = v
    validators = dict(validators or {})
    if check is not None:
        if "check_config" in validators:
            raise ValueError(f"{name}: validator name 'check_config' is taken by check=")
        def _check(self):
            check(self)
            return self

        validators["check_config"] = model_validator(mode="after")(_check)
    base = type(f"{name}Base", (BaseModel,), {"model_config": ConfigDict(extra="forbid"),
                                               "__module__": module or __name__, **(methods or {})})
    return create_model(name, __base__=base, __doc__=doc, __validators__=validators,
                        __module__=module or __name__, **defs)
