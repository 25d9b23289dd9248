"""One entry point by group and name: loaded, checked against a base class, and an unknown name said with the
installed ones."""

from __future__ import annotations

import pytest

from flexsheet.runtime.plugins import plugin
from flexsheet.vision.camera_port import CameraSource
from flexsheet.vision.head_camera_port import HeadCameraSource


def test_an_entry_is_loaded_and_checked_against_its_base():
    cls = plugin("flexsheet.camera_sources", "sim", what="camera source", base=CameraSource)
    assert cls.__name__ == "TwinCamera"
    with pytest.raises(LookupError, match=r"camera source 'sim' \(flexsheet.camera_sources\) is "
                                          r".*TwinCamera.*, not a HeadCameraSource"):
        plugin("flexsheet.camera_sources", "sim", what="camera source", base=HeadCameraSource)


def test_an_unknown_name_and_an_empty_group_are_said():
    with pytest.raises(LookupError, match=r"unknown bench 'nope' \(flexsheet.benches\); known: .*sim"):
        plugin("flexsheet.benches", "nope", what="bench")
    with pytest.raises(LookupError, match=r"known: none \(is flexsheet installed"):
        plugin("flexsheet.no_such_group", "x")


def test_a_source_param_is_any_installed_entry_and_an_unknown_one_is_refused_naming_the_installed():
    from pydantic import TypeAdapter, ValidationError

    from flexsheet.runtime.plugins import EntryName

    source = TypeAdapter(EntryName("flexsheet.controller_sources", "controller source"))
    assert source.validate_python("tcp") == "tcp"
    assert source.validate_python("sim") == "sim"
    with pytest.raises(ValidationError, match=r"unknown controller source 'udp'; installed: sim, tcp"):
        source.validate_python("udp")

