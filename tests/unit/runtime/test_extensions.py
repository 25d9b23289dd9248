"""Launch extensions (flexsheet/runtime/extensions.py): the display's sections reach the runtime only through
the ``flexsheet.launch_extensions`` entry point (and the bag channels through theirs)."""

from __future__ import annotations

import pytest

from flexsheet.runtime.extensions import bag_channels, extensions, sections


def test_the_display_extension_is_installed_with_its_three_sections():
    assert [e.name for e in extensions()] == ["display"]
    assert sorted(sections()) == ["display_calib", "scene", "twin"]
    assert bag_channels("foxglove").__module__ == "flexsheet.viz.foxglove_bag"
    with pytest.raises(LookupError, match="no bag channels named 'nope'"):
        bag_channels("nope")
