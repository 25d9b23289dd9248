"""The projector output port: the renderer's window is an entry point, named by the node's ``output``."""

from __future__ import annotations

import pytest

from flexsheet.rendering.output_port import OUTPUTS_GROUP, projector_output


def test_the_window_is_the_installed_output_and_an_unknown_one_is_named_with_it():
    window = projector_output("window")
    assert window.__name__ == "WindowOutput" and window.__module__ == "nodes.renderer.window"
    with pytest.raises(LookupError, match=rf"unknown projector output 'hdmi' \({OUTPUTS_GROUP}\); "
                                          r"known: window"):
        projector_output("hdmi")
