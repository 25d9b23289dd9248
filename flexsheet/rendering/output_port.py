"""The projector output port: the window the renderer shows its pairs in.

The renderer node draws offscreen (``output: offscreen``) or into the projector's window (``output: window``),
a device. The window's class is an entry point of the group :data:`OUTPUTS_GROUP` (``pyproject.toml``):
``window``, a glfw window on a monitor (``nodes/renderer/window.py``). It is built as
``projector_output("window")(projector, stereo=…, monitor=…, fullscreen=…, refresh_hz=…, …)`` on the thread
that will use it (no current EGL context there). It holds the
:class:`~flexsheet.rendering.stereo_renderer.StereoRenderer` drawing on its OpenGL context (``.renderer``),
the window (``.window``: ``swap()``, ``poll()``, ``refresh_hz``, ``pacing``), the eyes' presenter
(``.presenter``: ``draw(eye)``, ``frame_size``) and its :class:`~flexsheet.rendering.pacing.FramePacer`
(``.pacer``); ``close()`` ends it.
"""

from __future__ import annotations

from flexsheet.runtime.plugins import plugin

__all__ = ["OUTPUTS_GROUP", "projector_output"]

#: the entry-point group of the projector outputs (name: the renderer node's ``output`` param)
OUTPUTS_GROUP = "flexsheet.projector_outputs"


def projector_output(name: str) -> type:
    """The output class installed as ``name`` in :data:`OUTPUTS_GROUP`. Raises ``LookupError`` naming the
    installed ones."""
    return plugin(OUTPUTS_GROUP, name, what="projector output")  # type: ignore[return-value]
