"""The head camera port: its sources are entry points, named by a head camera node's ``source``."""

from __future__ import annotations

import pytest

from flexsheet.twin.head_camera_source import TwinHeadCamera
from flexsheet.vision.head_camera_port import SOURCES_GROUP, HeadCameraSource, head_camera_source


def test_the_installed_sources_are_the_twin_and_the_uvc_camera():
    assert head_camera_source("sim") is TwinHeadCamera
    dev = head_camera_source("device")
    assert issubclass(dev, HeadCameraSource) and dev.blocking and not TwinHeadCamera.blocking
    assert dev.__module__ == "nodes.head_camera.uvc"


def test_an_unknown_source_is_named_with_the_installed_ones():
    with pytest.raises(LookupError, match=rf"unknown head camera source 'gige' \({SOURCES_GROUP}\); known: "
                                          r"device, sim"):
        head_camera_source("gige")


def test_the_uvc_probe_names_a_missing_device():
    from types import SimpleNamespace

    lines = head_camera_source("device").probe(SimpleNamespace(device="/dev/video_nothing_here",
                                                               rate_hz=60.0))
    assert lines == ["head camera: cannot open UVC device '/dev/video_nothing_here' (cv2.VideoCapture)"]
