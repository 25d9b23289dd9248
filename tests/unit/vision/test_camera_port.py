"""The stereo camera port: its sources are entry points, named by the camera node's ``source``."""

from __future__ import annotations

import pytest

from flexsheet.twin.camera_source import TwinCamera
from flexsheet.vision.camera_port import SOURCES_GROUP, CameraSource, camera_source


def test_the_installed_sources_are_the_twin_and_the_lab_cameras():
    assert camera_source("sim") is TwinCamera and TwinCamera.models_link_delay
    lab = {name: camera_source(name) for name in ("genicam", "device", "files")}
    assert all(issubclass(c, CameraSource) and c.__module__ == "nodes.camera.sources"
               and not c.models_link_delay
               for c in lab.values())
    assert [c.__name__ for c in lab.values()] == ["GenICamCamera", "UvcCamera", "FilesCamera"]


def test_an_unknown_source_is_named_with_the_installed_ones():
    with pytest.raises(LookupError, match=rf"unknown camera source 'v4l' \({SOURCES_GROUP}\); known: device, "
                                          r"files, genicam, sim"):
        camera_source("v4l")


def test_only_an_ideal_twin_claims_the_nominal_registration_exact():
    from types import SimpleNamespace

    from flexsheet.model.truth_choice import TruthChoice

    ideal, real = (SimpleNamespace(twin=TruthChoice(realism=r)) for r in ("ideal", "realistic"))
    assert TwinCamera.exact_nominal_registration(ideal) and not TwinCamera.exact_nominal_registration(real)
    assert not camera_source("device").exact_nominal_registration(ideal)
