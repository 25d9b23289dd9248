"""Multipart frames on a ZeroMQ socket without blocking: pyzmq's flags as plain ints (its enum flags cost a
Python enum operation each, measurable per message), :func:`send_frames`, :func:`drain_sub`,
:func:`frame_nbytes`."""

from __future__ import annotations

import zmq

from flexsheet.runtime.transport import FramesHandler

__all__ = ["EVENTS", "POLLIN", "NOBLOCK", "RCVMORE", "SNDMORE", "NOBLOCK_MORE", "send_frames", "frame_nbytes",
           "drain_sub"]

# plain ints: pyzmq's enum flags cost a Python enum operation each (measurable per message)
EVENTS, POLLIN, NOBLOCK, RCVMORE = int(zmq.EVENTS), int(zmq.POLLIN), int(zmq.NOBLOCK), int(zmq.RCVMORE)
SNDMORE = int(zmq.SNDMORE)
NOBLOCK_MORE = NOBLOCK | SNDMORE


def send_frames(sock: zmq.Socket, frames: list) -> None:
    """Send one multipart message without blocking (``send_multipart`` minus its per-frame enum
    arithmetic)."""
    send = sock.send
    last = len(frames) - 1
    for i, f in enumerate(frames):
        send(f, NOBLOCK_MORE if i < last else NOBLOCK, copy=False)


def frame_nbytes(frame) -> int:
    """Size of one frame that is not ``bytes`` (an array, a memoryview, a ``zmq.Frame``), bytes."""
    n = getattr(frame, "nbytes", None)
    return n if n is not None else len(frame)


def drain_sub(sub: zmq.Socket | None, handler: FramesHandler) -> None:
    """Receive every message ready on ``sub`` without blocking and hand each to ``handler`` as a list of
    frames: the topic and meta frames as ``bytes`` (small: a copy is cheaper to hand on than a ``zmq.Frame``),
    the array buffers as zero-copy ``zmq.Frame`` objects. After the first frame the frames' own ``more`` flag
    says whether another follows (each ``getsockopt`` call costs pyzmq an enum lookup, ~1 µs)."""
    if sub is None or sub.closed:
        return
    recv, getsockopt = sub.recv, sub.getsockopt
    while getsockopt(EVENTS) & POLLIN:
        try:
            frames = [recv(NOBLOCK)]
        except zmq.Again:
            break
        if getsockopt(RCVMORE):
            f = recv(NOBLOCK, copy=False)
            frames.append(f.bytes)
            while f.more:
                f = recv(NOBLOCK, copy=False)
                frames.append(f)
        handler(frames)

