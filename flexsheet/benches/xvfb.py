"""A private X server (Xvfb) for testing and benchmarking the projector window without a monitor, and a
screenshot of it read back through X (not through OpenGL).

:func:`xvfb` starts ``Xvfb -displayfd`` so the server itself picks a free display number (no guessing, no race
with other servers on the machine) and yields the ``DISPLAY`` string. :func:`grab` reads the root window over
XCB with Pillow's ``ImageGrab`` (``GetImage`` on the X server): an independent path from the GL read-back, so
a screenshot shows what X actually received from the window's buffer swap. Mesa's llvmpipe gives GLX 4.5 on
Xvfb; there is no vsync there (swaps return at once), so the window paces itself by a timer (the projector
output port's ``window``, :mod:`flexsheet.rendering.output_port`). Debian packages: ``xvfb``; Pillow comes
with matplotlib. Not the renderer's device I/O: the node opens its window on whatever ``DISPLAY`` it is
given; the render bench and the window's tests start this server for it.
"""

from __future__ import annotations

import contextlib
import ctypes
import os
import select
import shutil
import signal
import subprocess
import time
from collections.abc import Iterator

import numpy as np

__all__ = ["xvfb", "grab", "XvfbError"]


class XvfbError(RuntimeError):
    """Xvfb is missing or did not start (message names the reason)."""


def _die_with_parent() -> None:  # pragma: no cover - runs in the child between fork and exec
    """SIGTERM the server when the thread that started it dies (a test killed by a fatal X error must not
    leave its Xvfb behind). Linux ``prctl(PR_SET_PDEATHSIG)``; a no-op elsewhere."""
    try:
        ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGTERM)   # PR_SET_PDEATHSIG = 1
    except (OSError, AttributeError):
        pass


@contextlib.contextmanager
def xvfb(width: int = 1280, height: int = 1024, depth: int = 24, timeout: float = 20.0) -> Iterator[str]:
    """Run a private Xvfb screen of ``width × height`` px at ``depth`` bits for the ``with`` block; yields its
    ``DISPLAY`` (":N"). The server is stopped on exit, and by the kernel if the calling thread dies first
    (call it from a thread that outlives the block, e.g. the main thread). Raises :class:`XvfbError` if Xvfb
    is not installed or does not report its display within ``timeout`` s."""
    exe = shutil.which("Xvfb")
    if exe is None:
        raise XvfbError("Xvfb is not installed (Debian package 'xvfb')")
    r, w = os.pipe()
    proc = subprocess.Popen([exe, "-displayfd", str(w), "-screen", "0", f"{width}x{height}x{depth}",
                             "-nolisten", "tcp", "-noreset"], pass_fds=(w,), stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE, preexec_fn=_die_with_parent)
    os.close(w)
    try:
        buf = b""
        end = time.monotonic() + timeout
        while not buf.endswith(b"\n"):
            left = end - time.monotonic()
            if left <= 0 or proc.poll() is not None:
                err = proc.stderr.read().decode(errors="replace")[-400:] if proc.poll() is not None else ""
                raise XvfbError(f"Xvfb did not start within {timeout} s: {err.strip()}")
            ready, _, _ = select.select([r], [], [], min(left, 0.5))
            if ready:
                chunk = os.read(r, 64)
                if not chunk:
                    continue
                buf += chunk
        yield ":" + buf.decode().strip()
    finally:
        os.close(r)
        proc.terminate()
        try:
            proc.wait(timeout=5)
        except subprocess.TimeoutExpired:  # pragma: no cover
            proc.kill()
            proc.wait()
        proc.stderr.close()


def grab(display: str, bbox: tuple[int, int, int, int] | None = None) -> np.ndarray:
    """Screenshot of X ``display`` (":N") as (h, w, 3) uint8 RGB, top row first; ``bbox`` = (left, top, right,
    bottom) in screen pixels (None: the whole screen). Raises ``RuntimeError`` if Pillow lacks XCB support."""
    from PIL import ImageGrab, features

    if not features.check("xcb"):
        raise RuntimeError("Pillow was built without XCB support: cannot read the X screen")
    img = ImageGrab.grab(bbox=bbox, xdisplay=display)
    return np.ascontiguousarray(np.asarray(img.convert("RGB")))
