"""Vision messages: stereo frames, the stereo calibration (latched) and the fingertip estimate."""

from __future__ import annotations

from pydantic import Field

from messages.common import Message, ndarray

__all__ = ["StereoFrame", "StereoCalibration", "Fingertip", "EyePose"]


class StereoFrame(Message):
    """A synchronised stereo pair from the camera node (mono8).
    ``left``, ``right``: uint8 arrays of shape (H, W), raw (unrectified) images of the left and right camera.
    ``exposure_stamp``: mid-exposure time, s (sender's clock); ``header.stamp``: the time the frame was handed
    to the graph (after readout/transfer; for the twin, after rendering), s. ``exposure_time``: shutter time,
    s. ``stereo_skew``: right minus left exposure time, s (0 for a hardware-synchronised pair; a receiver
    rejects pairs whose |skew| exceeds its tolerance). ``header.frame_id`` is the left camera's optical frame
    (``"camera_left"``: +z forward, +x right, +y down, OpenCV convention).
    """

    SCHEMA = "flexsheet/StereoFrame"
    VERSION = 1

    left: ndarray("uint8", (None, None), "left image, mono8, (H, W)")
    right: ndarray("uint8", (None, None), "right image, mono8, (H, W)")
    exposure_stamp: float = Field(description="mid-exposure time, s (sender's clock)")
    exposure_time: float = Field(ge=0.0, description="shutter open time, s")
    stereo_skew: float = Field(default=0.0, description="right minus left exposure time, s")


class StereoCalibration(Message):
    """Stereo calibration of the camera pair, published latched (same content as ``calibrate stereo``'s YAML).
    Intrinsics ``K1``, ``K2`` (3, 3) in px; distortion ``D1``, ``D2`` (5,) OpenCV (k1, k2, p1, p2, k3);
    ``R`` (3, 3) and ``T`` (3,) in m map left-camera coordinates to right-camera coordinates
    (x_r = R x_l + T, OpenCV ``stereoCalibrate``); rectification ``R1``, ``R2`` (3, 3), projections
    ``P1``, ``P2`` (3, 4) px, ``Q`` (4, 4). ``T_display_camera`` (4, 4): pose of the left camera optical
    frame in the display frame (m). ``image_size`` (2,) int64 is (width, height) in px.
    """

    SCHEMA = "flexsheet/StereoCalibration"
    VERSION = 1

    image_size: ndarray("int64", (2,), "(width, height), px")
    K1: ndarray("float64", (3, 3), "left camera matrix, px")
    D1: ndarray("float64", (None,), "left distortion (k1, k2, p1, p2, k3)")
    K2: ndarray("float64", (3, 3), "right camera matrix, px")
    D2: ndarray("float64", (None,), "right distortion (k1, k2, p1, p2, k3)")
    R: ndarray("float64", (3, 3), "rotation left->right camera")
    T: ndarray("float64", (3,), "translation left->right camera, m")
    R1: ndarray("float64", (3, 3), "left rectification rotation")
    R2: ndarray("float64", (3, 3), "right rectification rotation")
    P1: ndarray("float64", (3, 4), "left rectified projection, px")
    P2: ndarray("float64", (3, 4), "right rectified projection, px")
    Q: ndarray("float64", (4, 4), "disparity-to-depth matrix")
    T_display_camera: ndarray("float64", (4, 4), "pose of the left camera optical frame in the display "
                                                 "frame, m")
    rms_px: float = Field(default=0.0, ge=0.0, description="stereo RMS reprojection error, px")


class Fingertip(Message):
    """Triangulated fingertip marker position in the display frame.
    ``position`` (3,) m, display frame; ``covariance`` (3, 3) m², from pixel-noise propagation. ``valid`` is
    False when the marker is lost or gated out: then ``position`` is the zero vector and must not be used
    (never a stale or invented position). ``predicted_position`` (3,) m is the constant-velocity Kalman
    prediction ``prediction_horizon`` s ahead of ``header.stamp`` (horizon 0 when the predictor is off; then
    it equals ``position``). ``exposure_stamp`` (s) is the camera exposure the estimate comes from,
    ``frame_stamp`` (s) the time that frame was published by the camera node (its ``header.stamp``) and
    ``sent_stamp`` (s) the time this estimate was published, all carried for latency accounting.
    ``reprojection_px``: epipolar/reprojection residual, px.
    """

    SCHEMA = "flexsheet/Fingertip"
    VERSION = 1

    position: ndarray("float64", (3,), "marker position, m, display frame")
    covariance: ndarray("float64", (3, 3), "position covariance, m^2")
    valid: bool = Field(description="False when the marker is lost, occluded or gated out")
    predicted_position: ndarray("float64", (3,), "predicted position at stamp + horizon, m, display frame")
    prediction_horizon: float = Field(default=0.0, ge=0.0, description="prediction horizon, s")
    exposure_stamp: float = Field(description="exposure time of the source frame, s")
    frame_stamp: float = Field(default=0.0, description="time the source stereo frame was published, s")
    sent_stamp: float = Field(default=0.0, description="time this estimate was published, s")
    reprojection_px: float = Field(default=0.0, ge=0.0, description="epipolar residual, px")


class EyePose(Message):
    """The viewer's tracked glasses and eyes from the head camera (:mod:`flexsheet.vision.glasses`).
    ``header.stamp`` is the frame's mid-exposure time (s). ``position`` (3,) m and ``rotation`` (3, 3) (axes
    as columns): the glasses frame in the display frame; ``left``/``right``/``eye`` (3,) m: both eyes and
    their midpoint, display frame, at the stamp (the eye offset and IPD are the lab's measured ones);
    ``velocity`` (3,) m/s of the midpoint, for prediction to photon time. ``valid`` False: the glasses were
    not found (the geometry then repeats the last good pose, or V before any; ``age`` says how old it is).
    ``markers``: board markers used; ``reprojection_px``: RMS PnP residual, px.
    """

    SCHEMA = "flexsheet/EyePose"
    VERSION = 1

    position: ndarray("float64", (3,), "glasses origin, m, display frame")
    rotation: ndarray("float64", (3, 3), "glasses axes as columns, display frame")
    left: ndarray("float64", (3,), "left eye, m, display frame")
    right: ndarray("float64", (3,), "right eye, m, display frame")
    eye: ndarray("float64", (3,), "cyclopean eye, m, display frame")
    velocity: ndarray("float64", (3,), "cyclopean eye velocity, m/s, display frame")
    valid: bool = Field(description="glasses found in this frame")
    age: float = Field(default=0.0, ge=0.0, description="age of the pose carried when not valid, s")
    markers: int = Field(default=0, ge=0, description="board markers used")
    reprojection_px: float = Field(default=0.0, ge=0.0, description="RMS PnP reprojection error, px")
