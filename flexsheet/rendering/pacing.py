"""Frame pacing and stereo frame layout for the projector window, pure (no GL, no window system).

* :class:`FramePacer` counts vsyncs from the times at which buffer swaps complete, detects missed vsyncs, and
  says which eye the next frame is for in frame-sequential stereo. The eye follows the **vsync count**, not a
  frame counter: with active-shutter glasses (the paper's DepthQ projector with CrystalEyes) the glasses
  alternate on every refresh, so a dropped vsync (the projector shows the previous image once more) would swap
  the eyes for good if the program simply alternated per frame. Counting vsyncs re-synchronises at the very
  next frame. The count comes from the media stream counter (``GLX_OML_sync_control``) where the driver offers
  it, otherwise from the swap-completion times: ``n = round(Δt / period)`` vsyncs between two swaps (robust
  while the swap-return jitter stays under half a period, 4.2 ms at 120 Hz). The period is the monitor's
  refresh period, refined by a running mean over punctual intervals (within 10 %).
* :func:`frame_layout` says where each eye's image goes in the output frame for each stereo format.

Times in s (any monotonic clock), sizes in pixels, GL viewports (x, y, w, h) with y up from the bottom row.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import numpy as np

__all__ = ["FramePacer", "PacingStats", "frame_layout", "STEREO_MODES", "LEFT", "RIGHT"]

LEFT, RIGHT = 0, 1
STEREO_MODES = ("frame_sequential", "side_by_side", "top_bottom", "mono")


@dataclass(frozen=True)
class PacingStats:
    """Pacing over the last ``window`` frames: ``fps`` frames per s; ``interval_mean_ms``/``interval_p99_ms``
    between swaps; ``missed_vsyncs`` since start (refreshes that showed an old frame); ``eye_resyncs``: missed
    runs of odd length, where a per-frame eye counter would have swapped the eyes; ``frames`` since start;
    ``period_ms`` the refresh period in use; ``source`` "counter" (a vsync counter: the driver's media stream
    counter, or the window's timer grid) or "time" (inferred from swap times)."""

    frames: int
    fps: float
    interval_mean_ms: float
    interval_p99_ms: float
    missed_vsyncs: int
    eye_resyncs: int
    period_ms: float
    source: str

    def line(self) -> str:
        """One line for /diagnostics."""
        return (f"window {self.fps:.1f} fps (refresh {1e3 / self.period_ms:.1f} Hz), frame interval mean "
                f"{self.interval_mean_ms:.2f} ms p99 {self.interval_p99_ms:.2f} ms, missed vsyncs "
                f"{self.missed_vsyncs}, eye resyncs {self.eye_resyncs} [{self.source}]")


class FramePacer:
    """Vsync counter and eye chooser (see the module docstring).

    ``refresh_hz``: the display's refresh rate, Hz (> 0); ``window``: frames kept for the statistics;
    ``swap_eyes``: start with the right eye (for glasses whose phase is the other way round).
    Raises ``ValueError`` for a non-positive or non-finite rate.
    """

    def __init__(self, refresh_hz: float, window: int = 600, swap_eyes: bool = False) -> None:
        if not (math.isfinite(refresh_hz) and refresh_hz > 0.0):
            raise ValueError(f"refresh_hz must be finite and > 0, got {refresh_hz!r}")
        self.nominal_period = 1.0 / float(refresh_hz)
        self.period = self.nominal_period
        self.swap_eyes = bool(swap_eyes)
        self.vsync = -1                      # vsync index at which the last frame was shown
        self.frames = 0
        self.missed = 0
        self.resyncs = 0
        self._t: float | None = None
        self._msc: int | None = None
        self._source = "time"
        self._dt: deque[float] = deque(maxlen=window)

    def next_eye(self) -> int:
        """The eye (:data:`LEFT`/:data:`RIGHT`) of the frame that the next vsync will show: even vsyncs show
        the left eye (the right with ``swap_eyes``)."""
        return ((self.vsync + 1) % 2) ^ int(self.swap_eyes)

    def on_swap(self, t: float, msc: int | None = None) -> int:
        """Record a frame whose swap completed at time ``t`` s (and, if known, at media stream counter
        ``msc``). Returns the number of vsyncs since the previous frame (1 when on time; 0 for the first
        frame). Raises ``ValueError`` if time or the counter runs backwards."""
        if self._t is None:
            self._t, self._msc = float(t), msc
            self.vsync = 0 if msc is None else int(msc)
            self.frames = 1
            return 0
        dt = float(t) - self._t
        if dt < 0.0:
            raise ValueError(f"swap time went backwards by {-dt:.6f} s")
        if msc is not None and self._msc is not None:
            n = int(msc) - self._msc
            if n < 0:
                raise ValueError(f"media stream counter went backwards: {self._msc} -> {msc}")
            self._source = "counter"
        else:
            n = max(1, round(dt / self.period))
        if n == 1 and abs(dt - self.period) < 0.1 * self.period:
            # refine the period on punctual frames (the monitor's true rate, e.g. 119.98 Hz)
            self.period += 0.01 * (dt - self.period)
            self.period = min(max(self.period, 0.9 * self.nominal_period), 1.1 * self.nominal_period)
        if n > 1:
            self.missed += n - 1
            if (n - 1) % 2 == 1:
                self.resyncs += 1
        self.vsync += n
        self._t, self._msc = float(t), msc
        self.frames += 1
        self._dt.append(dt)
        return n

    def stats(self) -> PacingStats:
        """Statistics over the last ``window`` frames (zeros before two frames)."""
        d = np.asarray(self._dt, dtype=float)
        if len(d) == 0:
            return PacingStats(self.frames, 0.0, 0.0, 0.0, self.missed, self.resyncs, self.period * 1e3,
                               self._source)
        return PacingStats(self.frames, float(len(d) / d.sum()) if d.sum() > 0 else 0.0,
                           float(d.mean() * 1e3),
                           float(np.percentile(d, 99) * 1e3), self.missed, self.resyncs, self.period * 1e3,
                           self._source)


def frame_layout(stereo: str, width: int, height: int) -> tuple[tuple[int, int],
                                                                list[tuple[int | None, tuple]]]:
    """Output frame size and where each eye goes, for eye images of ``width × height`` px.

    Returns ((frame width, frame height), [(eye, viewport), ...]): ``eye`` is :data:`LEFT`, :data:`RIGHT` or
    None (frame-sequential: the eye of the current vsync, :meth:`FramePacer.next_eye`); ``viewport`` is the GL
    rectangle (x, y, w, h), y up from the bottom row.

    * ``frame_sequential``, ``mono``: one eye per frame, W × H (mono shows the left image, which the renderer
      draws from the cyclopean eye);
    * ``side_by_side``: 2W × H, left eye in the left half (full side-by-side: a half-SBS projector input is
      this with ``width`` = half the panel and the calibrated K, whose pixels are then twice as wide);
    * ``top_bottom``: W × 2H, left eye on top.

    Raises ``ValueError`` for an unknown format or a size below 1 px.
    """
    if width < 1 or height < 1:
        raise ValueError(f"eye image size must be >= 1x1 px, got {width}x{height}")
    W, H = int(width), int(height)
    if stereo == "frame_sequential":
        return (W, H), [(None, (0, 0, W, H))]
    if stereo == "mono":
        return (W, H), [(LEFT, (0, 0, W, H))]
    if stereo == "side_by_side":
        return (2 * W, H), [(LEFT, (0, 0, W, H)), (RIGHT, (W, 0, W, H))]
    if stereo == "top_bottom":
        return (W, 2 * H), [(LEFT, (0, H, W, H)), (RIGHT, (0, 0, W, H))]
    raise ValueError(f"stereo must be one of {STEREO_MODES}, got {stereo!r}")
