"""The finger camera twin's settings (:class:`SimConfig`): what it renders (finger, sheet, background), its
sensor (noise, blur, exposure, drops, measured on the real XIMEA pairs) and its timing. SI units; px and DN
where the key says so."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["SimConfig", "REALISTIC_DROP_RATE", "DEFAULT_FINGER_DIR", "XIMEA_SENSOR"]


#: dropped-frame rate of the realistic twin (assumption: ~1 % on a loaded GigE/USB3 link; the GenICam
#: source counts the real drops in /diagnostics)
REALISTIC_DROP_RATE = 0.01


#: default finger direction (fingertip → hand, display frame): the hand in front of the sheet (+x), above
#: (+z) and to the camera's side (−y) of the fingertip — a right index finger reaching across, seen by the
#: camera over the back of the hand (see docs/vision.md, "Self-occlusion", for the sweep over directions)
DEFAULT_FINGER_DIR = (0.587, 0.492, 0.643)


#: sensor numbers measured on the real XIMEA pairs (module doc): read noise σ DN, shot gain DN/DN, PSF σ px
XIMEA_SENSOR = {"read_dn": 2.54, "shot_gain": 0.312, "blur_px": 0.54}


@dataclass
class SimConfig:
    """Renderer settings (m, s, DN, px; module doc). Defaults are the **realistic** twin (measured read and
    shot noise, optical blur, finger self-occlusion); :meth:`ideal` gives the idealised sensing of the
    earlier twin (2 DN read noise only, marker always drawn over the finger).

    ``finger_dir``: vector from the fingertip toward the hand, display frame; ``marker_setback``: the
    marker centre sits this far behind the capsule's tip along the finger, m; ``marker_ss``: ray-cast
    sub-samples per pixel side; ``noise_dn``: read noise σ, DN; ``shot_gain``: DN per DN; ``noise_scale``:
    multiplies the noise σ (stability sweeps); ``blur_px``: optical PSF σ, px; ``clutter``: draw the
    projected sheet image (else a flat grey); ``background_gain``: brightness of the diffuse scene (sheet,
    room, finger) relative to the retro-reflective marker — 0.5: the exposure set for a marker lit by a ring
    light at the camera, the sheet then at ≤ ~95 DN (a design choice of the lab; the stability chart sweeps
    it: the detector breaks between 0.5 and 1).
    """

    marker_diameter: float = 0.004
    marker_level: float = 235.0
    finger_level: float = 70.0
    finger_width: float = 0.016
    finger_length: float = 0.07
    finger_dir: tuple[float, float, float] = DEFAULT_FINGER_DIR
    self_occlusion: bool = True
    marker_setback: float = 0.004
    marker_ss: int = 6
    noise_dn: float = XIMEA_SENSOR["read_dn"]
    shot_gain: float = XIMEA_SENSOR["shot_gain"]
    noise_scale: float = 1.0
    blur_px: float = XIMEA_SENSOR["blur_px"]
    exposure_s: float = 0.004
    blur_samples: int = 5
    clutter: bool = True
    background_gain: float = 0.5
    seed: int = 0

    @classmethod
    def ideal(cls, **kw) -> SimConfig:
        """The idealised sensing of the earlier twin: read noise 2 DN only (no shot noise) and no
        self-occlusion (the marker drawn over the finger); optics, exposure and scene as the realistic one."""
        base = {"noise_dn": 2.0, "shot_gain": 0.0, "self_occlusion": False}
        base.update(kw)
        return cls(**base)

    def validate(self) -> None:
        """Raise ``ValueError`` naming the first out-of-range field."""
        if not (0.001 <= self.marker_diameter <= 0.02):
            raise ValueError(f"marker_diameter must be in [0.001, 0.02] m, got {self.marker_diameter!r}")
        for name in ("marker_level", "finger_level"):
            if not (0 <= getattr(self, name) <= 255):
                raise ValueError(f"{name} must be in [0, 255] DN, got {getattr(self, name)!r}")
        if not (0.0 < self.background_gain <= 2.0):
            raise ValueError(f"background_gain must be in (0, 2], got {self.background_gain!r}")
        for name in ("noise_dn", "shot_gain", "noise_scale", "blur_px", "exposure_s", "marker_setback"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0):
                raise ValueError(f"{name} must be finite and >= 0, got {v!r}")
        if not (0.002 <= self.finger_width <= 0.04 and 0.0 < self.finger_length <= 0.2):
            raise ValueError(f"finger_width must be in [0.002, 0.04] m and finger_length in (0, 0.2] m, got "
                             f"{self.finger_width!r}, {self.finger_length!r}")
        if self.blur_samples < 1:
            raise ValueError(f"blur_samples must be >= 1, got {self.blur_samples!r}")
        if not (1 <= self.marker_ss <= 16):
            raise ValueError(f"marker_ss must be in [1, 16], got {self.marker_ss!r}")
        fd = np.asarray(self.finger_dir, float)
        if fd.shape != (3,) or not np.all(np.isfinite(fd)) or np.linalg.norm(fd) < 1e-9:
            raise ValueError(f"finger_dir must be a finite non-zero (3,) vector, got {self.finger_dir!r}")
