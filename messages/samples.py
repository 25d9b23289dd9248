"""Valid sample messages built from the models' own field declarations (for fuzzing and load benchmarks).

Because the values come from the declarations (:func:`messages.common.array_spec`, required scalars), the
samples follow the wire contract as it changes. Pure: no I/O.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from messages.common import Message, array_spec

__all__ = ["sample_fields"]


def sample_fields(cls: type[Message], seed: int = 0, shapes: dict[str, tuple[int, ...]] | None = None,
                  image: Callable[[tuple[int, ...], np.random.Generator], np.ndarray] | None = None) -> dict:
    """Field values (all but ``header``) of a valid instance of message class ``cls``.

    Arrays take ``shapes[name]`` if given, else the declared shape with free dimensions set to 2; uint8 arrays
    of ≥ 2 dims come from ``image(shape, rng)`` if given; ``faces`` index the ``vertices`` built before them;
    other integer arrays get values in 0..254, floats in [0.1, 0.9). Required scalars get True / 0.5 / 1 /
    ``"left"`` (for a ``left|right`` pattern) or ``"ok"``, a list of strings two ``"ok"``. Deterministic given
    ``seed``. Raises ``TypeError`` for a field kind it cannot fill.
    """
    rng = np.random.default_rng(seed)
    kw: dict = {}
    for name, info in cls.model_fields.items():
        if name == "header":
            continue
        spec = array_spec(info)
        if spec is not None:
            shape = (shapes or {}).get(name) or tuple(2 if s is None else s for s in (spec.shape or (3,)))
            dt = np.dtype(spec.dtype or "float64")
            if image is not None and dt == np.uint8 and len(shape) >= 2:
                kw[name] = image(shape, rng)
            elif name == "faces" and "vertices" in kw:
                kw[name] = rng.integers(0, len(kw["vertices"]), shape).astype(dt)
            elif dt.kind in "iu":
                kw[name] = rng.integers(0, 255, shape).astype(dt)
            else:
                kw[name] = rng.uniform(0.1, 0.9, shape).astype(dt)
        elif info.is_required():
            ann = info.annotation
            pattern = next((getattr(m, "pattern", None) for m in info.metadata
                            if getattr(m, "pattern", None)), None)
            if ann is bool:
                kw[name] = True
            elif ann is float:
                kw[name] = 0.5
            elif ann is int:
                kw[name] = 1
            elif ann is str:
                kw[name] = "left" if pattern and "left" in pattern else "ok"
            elif ann == list[str]:
                kw[name] = ["ok", "ok"]             # one per row of the free dimension (2)
            else:
                raise TypeError(f"{cls.__name__}.{name}: no sample for {ann}")
    return kw
