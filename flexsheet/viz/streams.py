"""Which Foxglove outputs are due and their bytes (:class:`FoxgloveStreams`, :class:`Rates`): the live bridge
and the bag writer share it."""

from __future__ import annotations

import json
import math
from collections.abc import Callable
from dataclasses import dataclass

from flexsheet.viz.foxglove import (
    CAMERA_LEFT,
    CAMERA_LEFT_INFO,
    CAMERA_RIGHT,
    CAMERA_RIGHT_INFO,
    JSON_TOPICS,
    METRICS,
    RENDER_IMAGE,
    SCENE,
    TF,
)
from flexsheet.viz.scene_builder import SceneBuilder
from messages import (
    Message,
)
from messages import topics as T

__all__ = ["Rates", "FoxgloveStreams", "Output"]


@dataclass
class Rates:
    """Output rates, Hz (0 turns an output off): ``scene`` (/viz/scene, /viz/tf, /viz/metrics), ``camera``
    (the camera images), ``render`` (/render/image), ``json`` (cap per JSON topic), ``calibration``."""

    scene: float = 10.0
    camera: float = 5.0
    render: float = 5.0
    json: float = 50.0
    calibration: float = 0.5

    def __post_init__(self) -> None:
        for k in ("scene", "camera", "render", "json", "calibration"):
            v = getattr(self, k)
            if not (math.isfinite(v) and v >= 0.0):
                raise ValueError(f"rate {k} must be finite and >= 0 Hz, got {v!r}")


#: one Foxglove output: (topic, payload bytes, log time in s)
Output = tuple[str, bytes, float]


class FoxgloveStreams:
    """Decides which Foxglove outputs are due and encodes them (protobuf or JSON bytes).

    ``on_message(topic, msg, t)`` stores the input and returns the JSON copy if its topic is due;
    ``poll(t, wanted)`` returns the scene/tf/metrics/images that are due at time ``t`` (s) and have changed
    input since they were last sent. ``wanted(topic)`` lets the live bridge skip outputs nobody subscribes
    to (nothing is built for them). Input that the builder rejects raises ``ValueError`` (counted by callers).
    """

    def __init__(self, builder: SceneBuilder | None = None, rates: Rates | None = None) -> None:
        self.builder = builder or SceneBuilder()
        self.rates = rates or Rates()
        self._last: dict[str, float] = {}
        self._dirty: set[str] = set()
        self.built: dict[str, int] = {}

    def _due(self, key: str, rate: float, t: float) -> bool:
        """True (and the slot taken) if output ``key`` at ``rate`` Hz is due at ``t`` s. Drift-free: slots are
        ``last + 1/rate``, so polling at an unrelated rate still averages ``rate``; time going back by more
        than a period (a bag played in a loop) is due."""
        if rate <= 0:
            return False
        period = 1.0 / rate
        last = self._last.get(key)
        if last is not None and last - period <= t < last + 0.999 * period:
            return False
        self._last[key] = last + period if last is not None and t < last + 2.0 * period and t >= last else t
        return True

    def rearm(self) -> None:
        """Make every output due at the next :meth:`poll` (scene, tf and metrics are sent even unchanged)."""
        self._last.clear()

    def on_message(self, topic: str, msg: Message, t: float,
                   wanted: Callable[[str], bool] = lambda _t: True) -> list[Output]:
        """Store ``msg`` (raises ``ValueError`` if unusable) and return its JSON copy if due and wanted."""
        self.builder.update(topic, msg)
        self._dirty.add(topic)
        if topic in _JSON_NAMES and wanted(topic) and self._due(topic, self.rates.json, t):
            return [(topic, self.builder.json_copy(topic, msg), t)]
        return []

    def poll(self, t: float, wanted: Callable[[str], bool] = lambda _t: True) -> list[Output]:
        """Outputs due at ``t`` s whose inputs changed since they were last sent (see class docstring)."""
        b, r, out = self.builder, self.rates, []
        dirty, self._dirty = self._dirty, set()
        if dirty - {T.STEREO.name, T.RENDERED.name, T.DIAGNOSTICS.name} or SCENE not in self._last:
            if wanted(SCENE) or wanted(TF) or wanted(METRICS):
                if self._due(SCENE, r.scene, t):
                    if wanted(SCENE):
                        out.append((SCENE, b.scene_bytes(t), t))
                    if wanted(TF):
                        out.append((TF, b.transforms(t).encode(), t))
                    if wanted(METRICS):
                        out.append((METRICS, json.dumps(b.metrics()).encode(), t))
                else:
                    self._dirty |= dirty  # not yet due: keep the change for the next poll
        if T.STEREO.name in dirty and (wanted(CAMERA_LEFT) or wanted(CAMERA_RIGHT)):
            if self._due(CAMERA_LEFT, r.camera, t):
                left, right = b.camera_images()
                out += [(CAMERA_LEFT, left.encode(), t), (CAMERA_RIGHT, right.encode(), t)]
            else:
                self._dirty.add(T.STEREO.name)
        if b.get(T.CALIBRATION) is not None and (wanted(CAMERA_LEFT_INFO) or wanted(CAMERA_RIGHT_INFO)):
            if T.CALIBRATION.name in dirty or self._due(CAMERA_LEFT_INFO, r.calibration, t):
                self._last[CAMERA_LEFT_INFO] = t
                cl, cr = b.calibrations()
                out += [(CAMERA_LEFT_INFO, cl.encode(), t), (CAMERA_RIGHT_INFO, cr.encode(), t)]
        if T.RENDERED.name in dirty and wanted(RENDER_IMAGE):
            if self._due(RENDER_IMAGE, r.render, t):
                out.append((RENDER_IMAGE, b.render_image().encode(), t))
            else:
                self._dirty.add(T.RENDERED.name)
        for topic, _, _ in out:
            self.built[topic] = self.built.get(topic, 0) + 1
        return out


_JSON_NAMES = {t.name for t in JSON_TOPICS}
