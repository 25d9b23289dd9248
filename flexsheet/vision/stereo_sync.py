"""Stereo pairing by device timestamp, device-to-host clock mapping, exposure skew and dropped frames.

Pure (numpy only, no Aravis): the GenICam wrapper (:mod:`nodes.camera.genicam`) feeds it one
:class:`CamFrame` per received buffer and gets :class:`StereoPair` s back; tests drive it with
synthetic frames.

Time bases
----------
Each camera stamps a frame with its own clock (``device_ns``; GigE Vision and USB3 Vision cameras latch
it at the frame start / start of exposure, vendor-dependent). Two cases:

* **shared device clock** (PTP IEEE 1588 locked on both cameras, or two fake cameras stamping with
  the same host clock): right − left device stamps *is* the exposure skew, exact to the PTP accuracy
  (< 1 µs on a switch with hardware time stamping). One host offset (the left camera's) maps both.
* **independent device clocks** (no PTP): each camera gets its own :class:`ClockMap` to host time
  (``time.time()``). The skew is then the difference of two mapped stamps and is only as good as the
  two offsets (see :class:`ClockMap`); with identical cameras on identical links the constant parts
  cancel and the residual is the jitter of the offset estimate.

Pairing (:class:`StereoPairer`): frames of each camera queue in arrival order; the two heads are paired
when their stamps differ by at most ``tolerance_s``, otherwise the older head can no longer find a
partner (stamps of a camera only increase) and is discarded as *unpaired*. Frames come out in order,
as soon as both halves are in. Source: the approximate-time policy of ROS ``message_filters``, reduced
to two queues with a fixed tolerance.

Dropped frames (:class:`FrameIdTracker`): GigE Vision numbers frames (block id, 16 bit, 0 skipped on
wrap, or 64 bit with extended ids); a gap in the sequence is a frame the camera sent that never
arrived (lost leader, buffer underrun). Buffers that arrive incomplete are counted separately by status.
"""

from __future__ import annotations

import collections
import math
import threading
from dataclasses import dataclass, field

import numpy as np

__all__ = ["CamFrame", "StereoPair", "FrameIdTracker", "ClockMap", "StereoPairer", "SkewStats"]


@dataclass(frozen=True)
class CamFrame:
    """One received frame of one camera.

    ``image``: uint8 (H, W) or None for an incomplete buffer; ``frame_id``: device frame counter;
    ``device_ns``: device timestamp, ns (device clock); ``arrival_s``: host time the buffer arrived, s
    (``time.time()`` clock; Aravis' system timestamp); ``status``: "ok" or the buffer status name.
    """

    image: np.ndarray | None
    frame_id: int
    device_ns: int
    arrival_s: float
    status: str = "ok"


@dataclass(frozen=True)
class StereoPair:
    """A paired stereo frame.

    ``left``/``right``: the two :class:`CamFrame`; ``stamp_s``: left frame's device stamp mapped to host
    time, s; ``skew_s``: right − left device stamp in the common time base, s; ``skew_basis``:
    ``"device_clock"`` (shared clock: PTP or one host clock) or ``"host_mapped"`` (independent clocks,
    each mapped to host time).
    """

    left: CamFrame
    right: CamFrame
    stamp_s: float
    skew_s: float
    skew_basis: str


class FrameIdTracker:
    """Counts frames missing from a camera's frame id sequence.

    ``update(frame_id)`` returns how many ids were skipped since the previous call (0 for the first).
    16-bit ids wrap after 65535 to 1 (GigE Vision 1.x: block id 0 is reserved) or to 0 (some devices,
    the Aravis fake camera): the tracker treats 0 as a valid id once it has seen one. An id that goes
    backwards by more than ``reset_window`` (camera restarted acquisition) starts a new sequence and
    counts nothing; a repeated or slightly older id (reordered delivery) counts nothing either.
    ``missing`` is the running total. Raises ``ValueError`` for a negative id.
    """

    WRAP16 = 1 << 16

    def __init__(self, reset_window: int = 1000) -> None:
        self.last: int | None = None
        self.missing = 0
        self.resets = 0
        self._seen_zero = False
        self._wide = False  # ids above 16 bit seen: 64-bit extended ids, no wrap
        self.reset_window = int(reset_window)

    def update(self, frame_id: int) -> int:
        fid = int(frame_id)
        if fid < 0:
            raise ValueError(f"frame_id must be >= 0, got {frame_id!r}")
        if fid == 0:
            self._seen_zero = True
        if fid >= self.WRAP16:
            self._wide = True
        last, self.last = self.last, fid
        if last is None:
            return 0
        if fid > last:
            gap = fid - last - 1
            if not self._wide and gap > self.WRAP16 - self.reset_window:  # a late frame from before a wrap
                self.last = last
                return 0
        elif not self._wide and last - fid > self.WRAP16 - self.reset_window:  # wrapped 65535 -> 0/1
            steps = (self.WRAP16 - last) + fid - (0 if self._seen_zero else 1)
            gap = max(steps - 1, 0)
        elif last - fid > self.reset_window:
            self.resets += 1
            return 0
        else:  # duplicate or reordered: keep the newest id
            self.last = last
            return 0
        self.missing += gap
        return gap


class ClockMap:
    """Maps one camera's device clock (ns) to host time (s, ``time.time()``).

    Two sources of the offset ``host − device``, best first:

    * **latch** (:meth:`add_latch`): the node latches the device clock (SFNC ``TimestampLatch`` /
      GigE ``GevTimestampControlLatch``) between two host clock reads ``t0``, ``t1``: offset =
      (t0 + t1)/2 − device, uncertainty (t1 − t0)/2 (half the GVCP round trip, typically 0.1–0.5 ms).
      Re-latched periodically, it follows the device clock's drift (10–50 ppm for camera crystals).
    * **arrival** (:meth:`add_arrival`): the passive lower-envelope estimate of Olson (2010, "A passive
      solution to the sensor synchronization problem", IROS): every frame gives an upper bound
      ``arrival − device`` of the offset plus the delivery delay; the estimate is
      ``min(previous + drift_bound × Δdevice, arrival − device)``, so it drops at once to a faster
      delivery and rises no faster than the clocks can drift (``drift_bound``, default 100 ppm). Delivery
      takes at least exposure + readout + transfer, so mapped stamps are late by that minimum delay, a
      constant for fixed settings: it cancels in the skew of two identical cameras on identical links, not
      in absolute latency figures (then :meth:`uncertainty` is NaN: unknown).

    :meth:`to_host` raises ``RuntimeError`` before any latch or frame. ``drift_bound`` must be ≥ 0
    (``ValueError``).
    """

    def __init__(self, drift_bound: float = 1e-4) -> None:
        if not drift_bound >= 0:
            raise ValueError(f"drift_bound must be >= 0, got {drift_bound!r}")
        self.drift_bound = float(drift_bound)
        self._est: float | None = None  # arrival estimate of host - device, s
        self._last_dev: float | None = None
        self._excess: collections.deque[float] = collections.deque(maxlen=100)  # delay above the envelope, s
        self._latch: tuple[float, float] | None = None  # (offset, uncertainty)
        self._lock = threading.Lock()

    def add_latch(self, device_ns: int, host_before_s: float, host_after_s: float) -> None:
        """Record a clock latch: device clock ``device_ns`` read between host times ``host_before_s`` and
        ``host_after_s`` (s). Raises ``ValueError`` if the host times are reversed."""
        if host_after_s < host_before_s:
            raise ValueError(f"latch host times reversed: {host_before_s!r} > {host_after_s!r}")
        off = 0.5 * (host_before_s + host_after_s) - device_ns * 1e-9
        with self._lock:
            self._latch = (off, 0.5 * (host_after_s - host_before_s))

    def add_arrival(self, device_ns: int, arrival_s: float) -> None:
        """Record one frame's device stamp (ns) and host arrival time (s)."""
        d = device_ns * 1e-9
        bound = arrival_s - d
        with self._lock:
            if self._est is None or self._last_dev is None or d < self._last_dev:
                self._est = bound  # first frame, or the device clock went back: restart the envelope
            else:
                self._est = min(self._est + self.drift_bound * (d - self._last_dev), bound)
            self._last_dev = d
            self._excess.append(bound - self._est)

    @property
    def method(self) -> str:
        """``"latch"``, ``"arrival"`` or ``"none"`` (nothing recorded yet)."""
        return "latch" if self._latch else ("arrival" if self._est is not None else "none")

    def offset(self) -> float:
        """Current host − device offset, s. Raises ``RuntimeError`` before any data."""
        with self._lock:
            if self._latch is not None:
                return self._latch[0]
            if self._est is None:
                raise RuntimeError("clock map has no latch and no frame yet")
            return self._est

    def uncertainty(self) -> float:
        """Latch: half the round trip, s. Arrival: NaN (late by the unknown minimum delivery delay)."""
        with self._lock:
            return self._latch[1] if self._latch is not None else math.nan

    def delivery_jitter(self) -> float:
        """Median delivery delay above the envelope over the last 100 frames, s (NaN before any frame):
        how much later than the fastest delivery a frame typically arrives."""
        with self._lock:
            return float(np.median(self._excess)) if self._excess else math.nan

    def to_host(self, device_ns: int) -> float:
        """Device stamp (ns) → host time (s)."""
        return device_ns * 1e-9 + self.offset()


class SkewStats:
    """Running statistics of |skew| over the last ``window`` pairs (s): p50, p99, max; plus the
    signed mean. ``summary()`` returns a dict (all in s; NaN when empty)."""

    def __init__(self, window: int = 2000) -> None:
        self._v: collections.deque[float] = collections.deque(maxlen=int(window))
        self._lock = threading.Lock()
        self.count = 0

    def add(self, skew_s: float) -> None:
        with self._lock:
            self._v.append(float(skew_s))
            self.count += 1

    def summary(self) -> dict:
        with self._lock:
            v = np.array(self._v, float)
        if v.size == 0:
            return {"skew_p50_s": math.nan, "skew_p99_s": math.nan, "skew_max_s": math.nan,
                    "skew_mean_s": math.nan, "pairs": self.count}
        a = np.abs(v)
        return {"skew_p50_s": float(np.percentile(a, 50)), "skew_p99_s": float(np.percentile(a, 99)),
                "skew_max_s": float(a.max()), "skew_mean_s": float(v.mean()), "pairs": self.count}


@dataclass
class _Side:
    queue: collections.deque = field(default_factory=collections.deque)
    ids: FrameIdTracker = field(default_factory=FrameIdTracker)
    clock: ClockMap = field(default_factory=ClockMap)
    received: int = 0
    incomplete: collections.Counter = field(default_factory=collections.Counter)
    unpaired: int = 0
    non_monotonic: int = 0
    last_device_ns: int | None = None


class StereoPairer:
    """Pairs left/right :class:`CamFrame` s by device timestamp (module doc).

    ``tolerance_s`` (> 0): largest |right − left| accepted as one pair; choose below half the frame
    period so neighbouring frames can never pair. ``shared_clock``: the two device clocks share a time
    base (PTP locked, or one host clock): skew = right − left device stamp; otherwise each side is mapped
    to host time by its own :class:`ClockMap`. ``max_queue``: frames kept per side while waiting for the
    partner (older ones are discarded as unpaired). ``on_pair`` is called (in the pushing thread, with the
    pairer's lock held, so pairs arrive in order; it must not call back into the pairer) with each
    :class:`StereoPair`. Thread-safe: :meth:`push` may be called from one thread per camera.
    Raises ``ValueError`` for a non-positive tolerance or a side other than 0/1.
    """

    def __init__(self, tolerance_s: float, shared_clock: bool, on_pair=None, max_queue: int = 8) -> None:
        if not tolerance_s > 0:
            raise ValueError(f"tolerance_s must be > 0, got {tolerance_s!r}")
        self.tolerance_s = float(tolerance_s)
        self.shared_clock = bool(shared_clock)
        self.on_pair = on_pair
        self.max_queue = int(max_queue)
        self.sides = (_Side(), _Side())
        self.skew = SkewStats()
        self.skew_other = SkewStats()  # the basis not used for pairing, for comparison (bench)
        self._lock = threading.Lock()

    @property
    def basis(self) -> str:
        """``"device_clock"`` (shared clock) or ``"host_mapped"``."""
        return "device_clock" if self.shared_clock else "host_mapped"

    def _skew(self, a: CamFrame, b: CamFrame) -> float:
        """right − left in the pairing basis, s (ns differences first: host times near 1.8e9 s would
        round to 0.2 µs)."""
        d = (b.device_ns - a.device_ns) * 1e-9
        if self.shared_clock:
            return d
        return d + (self.sides[1].clock.offset() - self.sides[0].clock.offset())

    def push(self, side: int, f: CamFrame) -> list[StereoPair]:
        """Add one frame of camera ``side`` (0 left, 1 right); returns the pairs completed (also passed
        to ``on_pair``). Incomplete frames (``status != "ok"``) are counted and not paired."""
        if side not in (0, 1):
            raise ValueError(f"side must be 0 (left) or 1 (right), got {side!r}")
        out: list[StereoPair] = []
        with self._lock:
            s = self.sides[side]
            s.received += 1
            s.ids.update(f.frame_id)
            if f.status != "ok" or f.image is None:
                s.incomplete[f.status] += 1
                return out
            if s.last_device_ns is not None and f.device_ns <= s.last_device_ns:
                s.non_monotonic += 1  # device clock went back (reset, PTP step): restart this side's queue
                s.unpaired += len(s.queue)
                s.queue.clear()
            s.last_device_ns = f.device_ns
            s.clock.add_arrival(f.device_ns, f.arrival_s)
            s.queue.append(f)
            while len(s.queue) > self.max_queue:
                s.queue.popleft()
                s.unpaired += 1
            L, R = self.sides
            while L.queue and R.queue:
                a, b = L.queue[0], R.queue[0]
                d = self._skew(a, b)
                if abs(d) <= self.tolerance_s:
                    L.queue.popleft()
                    R.queue.popleft()
                    out.append(StereoPair(a, b, L.clock.to_host(a.device_ns), d, self.basis))
                    self.skew.add(d)
                    raw = (b.device_ns - a.device_ns) * 1e-9
                    self.skew_other.add(raw if not self.shared_clock
                                        else raw + R.clock.offset() - L.clock.offset())
                elif d > 0:
                    L.queue.popleft()
                    L.unpaired += 1
                else:
                    R.queue.popleft()
                    R.unpaired += 1
            if self.on_pair is not None:  # under the lock: pairs reach the consumer in order
                for p in out:
                    self.on_pair(p)
        return out

    def stats(self) -> dict:
        """Counters per side (``left_*``/``right_*``: received, missing ids, incomplete by status,
        unpaired, queued (received = pairs + unpaired + incomplete + queued), non-monotonic stamps, clock
        method, its uncertainty s and delivery jitter s) and |skew| statistics (s)."""
        out: dict = {"skew_basis": self.basis, **self.skew.summary()}
        other = self.skew_other.summary()
        out["skew_other_basis"] = "host_mapped" if self.shared_clock else "device_clock"
        out["skew_other_p50_s"], out["skew_other_p99_s"] = other["skew_p50_s"], other["skew_p99_s"]
        with self._lock:
            for name, s in zip(("left", "right"), self.sides, strict=True):
                out[f"{name}_received"] = s.received
                out[f"{name}_missing_ids"] = s.ids.missing
                out[f"{name}_incomplete"] = int(sum(s.incomplete.values()))
                out[f"{name}_incomplete_by_status"] = dict(s.incomplete)
                out[f"{name}_unpaired"] = s.unpaired
                out[f"{name}_queued"] = len(s.queue)  # waiting for a partner
                out[f"{name}_non_monotonic"] = s.non_monotonic
                out[f"{name}_dropped"] = s.ids.missing + int(sum(s.incomplete.values()))
                out[f"{name}_clock"] = s.clock.method
                out[f"{name}_clock_uncertainty_s"] = s.clock.uncertainty()
                out[f"{name}_delivery_jitter_s"] = s.clock.delivery_jitter()
        return out
