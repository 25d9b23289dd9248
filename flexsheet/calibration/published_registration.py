"""What the camera node publishes latched on ``/camera/calibration``: the stereo model with its rectification
and the camera's pose in the display frame, from ``display.yaml``'s camera entry (or the nominal registration
for a camera whose nominal pose is exact: the ideal twin)."""

from __future__ import annotations

import cv2
import numpy as np

from flexsheet.calibration.display_calib import nominal_display_calib
from flexsheet.calibration.display_calib_file import load_display_calib

__all__ = ["with_rectification", "published_registration"]


def with_rectification(st: dict) -> dict:
    """A stereo dict (image_size, K1, D1, K2, D2, R, T) completed with R1, R2, P1, P2, Q
    (``cv2.stereoRectify``, alpha 0) for :func:`flexsheet.vision.stereo_calibration.to_message`."""
    out = {k: np.asarray(st[k], float)
           for k in ("K1", "D1", "K2", "D2", "R", "T", "R1", "R2", "P1", "P2", "Q")
           if k in st}
    out["image_size"] = tuple(int(x) for x in st["image_size"])
    out["rms_px"] = float(st.get("rms_px", 0.0))
    if "R1" not in out:
        R1, R2, P1, P2, Q, _, _ = cv2.stereoRectify(out["K1"], out["D1"], out["K2"], out["D2"],
                                                    out["image_size"],
                                                    out["R"], out["T"].reshape(3, 1), alpha=0)
        out.update(R1=R1, R2=R2, P1=P1, P2=P2, Q=Q)
    return out


def published_registration(display_calib: str | None, calib: dict, exact_nominal: bool = False,
                           model: str = "") -> tuple[dict, np.ndarray, str]:
    """What ``/camera/calibration`` carries: (stereo dict, T_display_camera (4, 4), one line saying where they
    come from). The pose from ``display.yaml``'s camera entry (the file ``display_calib``), with its stereo
    model when it has one (the pose was fitted with it), else ``calib`` (the stereo file of camera ``model``,
    named in errors). Without ``display_calib``: the nominal registration when ``exact_nominal`` (the source's
    camera is the nominal one: the ideal twin). Raises ``ValueError`` naming the fix when ``display_calib`` is
    missing (lab sources, realistic twin), unreadable, lacks the camera entry, or its image size differs from
    the camera's."""
    size = tuple(int(v) for v in calib["image_size"])
    if display_calib:
        cam = load_display_calib(display_calib, require=("camera",)).camera
        stereo = cam.stereo if cam.stereo is not None else calib
        got = tuple(int(v) for v in stereo["image_size"])
        if got != size:
            raise ValueError(f"{display_calib}: camera entry is for {got[0]}x{got[1]} images but the "
                             f"camera delivers {size[0]}x{size[1]} (model {model!r}); re-run flexsheet "
                             "calibrate camera-pose with this camera")
        src = "display.yaml stereo" if cam.stereo is not None else "stereo file"
        return (with_rectification(stereo), np.asarray(cam.T_display_camera, float),
                f"pose from {display_calib} ({cam.provenance.source}, {cam.provenance.measured_at}), {src}")
    if exact_nominal:
        return (with_rectification(calib), nominal_display_calib().camera.T_display_camera.copy(),
                "nominal registration (ideal twin: exact)")
    raise ValueError("display_calib is not set: the camera's pose in the display frame comes from "
                     "display.yaml's camera entry. Lab: run `flexsheet calibrate camera-pose`; twin: "
                     "`flexsheet calibrate display --sim --truth-seed N --out DIR`; then name the file in "
                     "the launch file (`display_calib: DIR/display.yaml`) or in this node's params "
                     "(docs/calibration.md)")
