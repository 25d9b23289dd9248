"""The renderer node's projector window (:class:`WindowThread`, a part of
:class:`nodes.renderer.node.RendererNode`): ``output: window`` opens the window (the projector output port's
``window``, :mod:`flexsheet.rendering.output_port`: :class:`nodes.renderer.window.WindowOutput`, glfw) on a
thread of its own, which presents a frame on every vsync and redraws the pair there when inputs arrive (at
most ``max_render_rate``; published at ``publish_rate``); the heartbeat leads with the window's frame rate and
missed vsyncs."""

from __future__ import annotations

import asyncio
import concurrent.futures
import threading
import time

from flexsheet.rendering.output_port import projector_output
from messages import Heartbeat
from nodes.renderer.params import RendererParams

__all__ = ["WindowThread"]


class WindowThread:
    """The window half of the renderer node; it uses the node's ``params``, ``projector``,
    ``_renderer_kwargs``, ``_frame``, ``pub``, ``_reject``, ``_last_render``, ``_last_publish``, ``log`` and
    ``shutdown``."""

    async def _open_window(self) -> None:
        self._stop_window = threading.Event()
        self._redraw = threading.Event()
        ready: concurrent.futures.Future = concurrent.futures.Future()
        self._window_thread = threading.Thread(target=self._window_main, args=(ready,),
                                               name="renderer-window",
                                               daemon=True)
        self._window_thread.start()
        await asyncio.wrap_future(ready)      # a WindowError (ValueError) is a configuration error

    def _window_main(self, ready: concurrent.futures.Future) -> None:
        p: RendererParams = self.params
        try:
            out = projector_output(p.output)(self.projector, stereo=p.stereo, monitor=p.monitor,
                                             fullscreen=p.fullscreen, mirror_x=p.mirror_x,
                                             refresh_hz=p.refresh_hz, quad_buffer=p.quad_buffer,
                                             swap_eyes=p.swap_eyes, title=f"flexsheet {self.name}",
                                             **self._renderer_kwargs())
        except BaseException as exc:  # noqa: BLE001 - handed to setup, which reports it
            ready.set_exception(exc)
            return
        self.output, self.renderer = out, out.renderer
        if out.window.warnings:
            self.state_message = "; ".join(out.window.warnings)
        ready.set_result(None)
        try:
            self._window_loop(out)
        except Exception:  # noqa: BLE001 - the projector image is gone: say so and stop the node (respawn)
            self.errors_total += 1
            self.state_message = "projector window failed"
            self.log.exception("projector window failed; stopping the node")
            self.shutdown()
        finally:
            out.close()

    def _window_loop(self, out) -> None:
        p: RendererParams = self.params
        last_stats = 0.0
        while not self._stop_window.is_set():
            if not out.window.poll(keep_open=True):
                self.log.warning("projector window close request ignored (stop the node instead)")
            now = time.monotonic()
            if self._redraw.is_set() and now - self._last_render >= 1.0 / p.max_render_rate:
                self._redraw.clear()
                self._last_render = now
                publish = now - self._last_publish >= 1.0 / p.publish_rate
                try:
                    msg = self._frame(publish)
                except ValueError as exc:
                    self._loop.call_soon_threadsafe(self._reject, f"render: {exc}")
                    msg = None
                if msg is not None:
                    self._last_publish = now
                    self._loop.call_soon_threadsafe(self.pub.publish, msg)
            out.show()
            if now - last_stats >= 0.25:
                self.pacing = out.pacer.stats()          # read by heartbeat() in the loop thread
                last_stats = now

    def heartbeat(self) -> Heartbeat:
        """Diagnostics; with the window output the message leads with its frame rate and missed vsyncs."""
        hb = super().heartbeat()
        pacing = getattr(self, "pacing", None)
        if pacing is None:
            return hb
        w = self.output.window
        line = f"{pacing.line()} [pacing {w.pacing}, counter {w.counter}, quad buffer {w.quad_buffered}]"
        return hb.model_copy(update={"message": f"{line}; {hb.message}" if hb.message else line})

