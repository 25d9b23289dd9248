"""``flexsheet bench camera --genicam``: frame rate, exposure skew and dropped frames of a GenICam pair.

Without ``--left``/``--right`` it measures two Aravis fake GigE Vision cameras (``arv-fake-gv-camera-0.8``)
on 127.0.0.1 and 127.0.0.2, re-running itself in a private network namespace when 127.0.0.2 is not
assigned here (:mod:`flexsheet.benches.fakecam`); with serials it measures the lab's cameras. The pair is
opened as the camera node opens it: the stereo camera port's ``genicam`` source
(:func:`flexsheet.vision.camera_port.camera_source`) with the camera node's params (its node type's
``Params``), the bench standing in for the node as the source's host.

Keys (one flat JSON object with ``--json``; ``--out FILE`` writes it, ``--plot FILE.png`` draws the skew
histogram and the pair intervals):

* ``pair_rate_hz``, ``left_fps``, ``right_fps``: paired and intact frames per second over ``seconds``;
* ``skew_p50_ms``/``skew_p99_ms``/``skew_max_ms`` (|right − left|) and ``skew_mean_ms`` (signed), in the
  ``skew_basis`` the pairer used (``device_clock``: right − left device stamps, valid when the clocks are
  shared — PTP, or the fake cameras, which stamp with the host clock; ``host_mapped``: each stamp mapped
  to host time), and ``skew_other_*`` in the other basis for comparison;
* ``left_dropped``/``right_dropped`` (incomplete buffers + frame id gaps), ``*_unpaired``,
  ``*_incomplete_by_status``, ``*_missing_packets`` (Aravis stream counter);
* ``interval_p50_ms``/``interval_p99_ms``: spacing of consecutive left device stamps;
* ``delivery_p50_ms``/``delivery_p99_ms`` (fake cameras only, whose device clock is the host clock): host
  time the pair reached the consumer minus the left frame's device stamp.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import logging
import os
import subprocess
import sys
import threading
import time
from typing import Any

import numpy as np

from flexsheet.benches.fakecam import ENV_FLAG, addresses_ready, fake_pair, isolated
from flexsheet.runtime.plugins import node_class
from flexsheet.vision.camera_port import camera_source

__all__ = ["main", "measure", "camera_params"]

FAKE_SERIALS = ("FSLEFT01", "FSRIGHT01")


class _Host:
    """The bench as the ``genicam`` source's host (:class:`~flexsheet.vision.camera_port.CameraHost`): the
    camera node's ``params`` and a logger; the pairs themselves are counted, not published."""

    def __init__(self, params: Any) -> None:
        self.params = params
        self.log = logging.getLogger("flexsheet.bench.camera")
        self.published = 0

    def publish_pair(self, left: np.ndarray, right: np.ndarray, stamp: float, skew: float = 0.0) -> None:
        self.published += 1


def camera_params(left: str, right: str, **fields: Any) -> Any:
    """The camera node's params (its node type's ``Params``, validated as a launch file's) for the GenICam
    pair ``left``/``right`` (serials) with ``fields`` (``width``, ``height``, ``exposure_s``, ``rate_hz``,
    ``trigger``, ``trigger_line``, ``device_clock``, …). Raises ``ValueError`` naming a bad field."""
    return node_class("camera").Params(source="genicam", left_id=left, right_id=right, **fields)


async def _stream(params: Any, seconds: float, progress: bool, rows: list, lock: threading.Lock) -> dict:
    """Open the pair through the port, keep each pair's (stamp, skew, left/right device ns, arrival) in
    ``rows`` for ``seconds`` s, close it; its counters at closing."""
    src = await camera_source("genicam").open(_Host(params), {"image_size": (params.width, params.height)})
    st = src.genicam                        # the source's GenICam pair (its counters and pairer)
    forward = st.pairer.on_pair

    def on_pair(p) -> None:
        with lock:
            rows.append((p.stamp_s, p.skew_s, p.left.device_ns, p.right.device_ns, time.time()))
        forward(p)
    st.pairer.on_pair = on_pair
    try:
        t_end = time.monotonic() + seconds
        while time.monotonic() < t_end:
            await asyncio.sleep(min(1.0, max(0.0, t_end - time.monotonic())))
            if progress:
                print(f"[bench camera] {src.status_line()}", file=sys.stderr, flush=True)
    finally:
        await src.close()
    return st.stats()


def measure(params: Any, seconds: float, fake: bool, progress: bool = False) -> tuple[dict, dict]:
    """Stream the pair of the camera node's ``params`` (:func:`camera_params`) for ``seconds`` s; returns
    (flat figures dict (module doc), raw series dict: ``skew_ms``, ``interval_ms``). Raises ``ValueError``
    when the source cannot start (a camera not found, Aravis missing)."""
    lock = threading.Lock()
    rows: list[tuple[float, float, int, int, float]] = []
    s = asyncio.run(_stream(params, seconds, progress, rows, lock))
    with lock:
        r = np.array(rows, float) if rows else np.zeros((0, 5))
    el = max(s["elapsed_s"], 1e-9)
    skew_ms = r[:, 1] * 1e3
    interval_ms = np.diff(r[:, 2]) * 1e-6
    out = {
        "mode": "fake" if fake else "real", "seconds": round(el, 3), "rate_hz_requested": params.rate_hz,
        "width": params.width, "height": params.height, "trigger": s.get("trigger"),
        "ptp_locked": s.get("ptp_locked"),
        "skew_basis": s.get("skew_basis"), "pairs": int(s.get("pairs", 0)),
        "pair_rate_hz": round(s.get("pairs", 0) / el, 3),
        "left_fps": round((s["left_received"] - s["left_incomplete"]) / el, 3),
        "right_fps": round((s["right_received"] - s["right_incomplete"]) / el, 3),
    }
    for key, v in (("skew_p50_ms", "skew_p50_s"), ("skew_p99_ms", "skew_p99_s"),
                   ("skew_max_ms", "skew_max_s"), ("skew_mean_ms", "skew_mean_s"),
                   ("skew_other_p50_ms", "skew_other_p50_s"),
                   ("skew_other_p99_ms", "skew_other_p99_s")):
        out[key] = round(float(s.get(v, float("nan"))) * 1e3, 4)
    out["skew_other_basis"] = s.get("skew_other_basis")
    for side in ("left", "right"):
        for k in ("received", "dropped", "unpaired", "queued", "missing_ids", "incomplete"):
            out[f"{side}_{k}"] = int(s.get(f"{side}_{k}", 0))
        out[f"{side}_incomplete_by_status"] = s.get(f"{side}_incomplete_by_status", {})
        out[f"{side}_missing_packets"] = int(s.get(f"{side}_stream", {}).get("n_missing_packets", 0))
        out[f"{side}_clock"] = s.get(f"{side}_clock")
    if interval_ms.size:
        out["interval_p50_ms"] = round(float(np.percentile(interval_ms, 50)), 4)
        out["interval_p99_ms"] = round(float(np.percentile(interval_ms, 99)), 4)
    if fake and len(r):
        delivery = (r[:, 4] - r[:, 2] * 1e-9) * 1e3
        out["delivery_p50_ms"] = round(float(np.percentile(delivery, 50)), 4)
        out["delivery_p99_ms"] = round(float(np.percentile(delivery, 99)), 4)
    out["cpu_count"] = os.cpu_count()
    return out, {"skew_ms": skew_ms, "interval_ms": interval_ms}


def _plot(path: str, series: dict, fig_title: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(1, 2, figsize=(10, 3.6))
    ax[0].hist(series["skew_ms"], bins=60)
    ax[0].set_xlabel("stereo skew right − left (ms)")
    ax[0].set_ylabel("pairs")
    ax[1].plot(series["interval_ms"], ".", ms=2)
    ax[1].set_xlabel("pair #")
    ax[1].set_ylabel("left device-stamp interval (ms)")
    fig.suptitle(fig_title)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    """CLI ``flexsheet bench camera`` (argparse). Prints figures (``--json``: one flat JSON object)."""
    argv = list(sys.argv[1:] if argv is None else argv)
    p = argparse.ArgumentParser(prog="flexsheet bench camera", description=__doc__.splitlines()[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter,
                                epilog="example:\n  flexsheet bench camera --genicam --seconds 10 --json\n"
                                       "  flexsheet bench camera --genicam --left 21234567 --right 21234568 "
                                       "--trigger hardware --rate 48")
    p.add_argument("--genicam", action="store_true", help="measure a GenICam pair (the only mode so far)")
    p.add_argument("--left", default="", help="left camera serial (default: two fake cameras)")
    p.add_argument("--right", default="", help="right camera serial")
    p.add_argument("--seconds", type=float, default=10.0, help="streaming time, s (default 10)")
    p.add_argument("--rate", type=float, default=25.0, help="frame rate, Hz (default 25)")
    p.add_argument("--width", type=int, default=640)
    p.add_argument("--height", type=int, default=512)
    p.add_argument("--exposure", type=float, default=0.004, help="exposure, s (default 0.004)")
    p.add_argument("--trigger", default="", choices=["", "hardware", "master", "software", "free"],
                   help="sync (default: free for fake cameras, software for real ones)")
    p.add_argument("--trigger-line", default="Line1")
    p.add_argument("--device-clock", default="", choices=["", "auto", "shared", "independent"],
                   help="default: shared for fake cameras (they stamp with the host clock), auto otherwise")
    p.add_argument("--lost-permille", type=int, default=0,
                   help="fake right camera drops this many GVSP packets per thousand (drop counters)")
    p.add_argument("--json", action="store_true", help="print one flat JSON object")
    p.add_argument("--out", default="", help="also write the JSON to this file")
    p.add_argument("--plot", default="", help="write a PNG (skew histogram, pair intervals)")
    a = p.parse_args(argv)
    if not a.genicam:
        p.error("choose the camera kind: --genicam")
    if bool(a.left) != bool(a.right):
        p.error("give both --left and --right, or neither (fake cameras)")
    fake = not a.left
    if fake and not addresses_ready() and not os.environ.get(ENV_FLAG):
        try:
            cmd = isolated([sys.executable, "-m", "flexsheet.benches.camera", *argv])
        except RuntimeError as exc:
            print(f"flexsheet bench camera: {exc}", file=sys.stderr)
            return 2
        return subprocess.run(cmd).returncode
    try:
        cfg = camera_params(a.left or FAKE_SERIALS[0], a.right or FAKE_SERIALS[1], width=a.width,
                            height=a.height, exposure_s=a.exposure, rate_hz=a.rate,
                            trigger=a.trigger or ("free" if fake else "software"),
                            trigger_line=a.trigger_line,
                            device_clock=a.device_clock or ("shared" if fake else "auto"))
    except ValueError as exc:
        p.error(str(exc))
    who = "two fake cameras" if fake else f"{a.left} + {a.right}"
    print(f"[bench camera] {who}: {cfg.width}x{cfg.height} at {cfg.rate_hz} Hz, trigger {cfg.trigger}, "
          f"{a.seconds} s", file=sys.stderr, flush=True)
    try:
        if fake:
            with fake_pair(FAKE_SERIALS, lost_permille=(0, a.lost_permille)):
                out, series = measure(cfg, a.seconds, True, progress=True)
        else:
            out, series = measure(cfg, a.seconds, False, progress=True)
    except (ValueError, RuntimeError) as exc:
        print(f"flexsheet bench camera: {exc}", file=sys.stderr)
        return 2
    if a.lost_permille:
        out["right_lost_permille"] = a.lost_permille
    if a.out:
        with open(a.out, "w") as fh:
            json.dump(out, fh, indent=1)
    if a.plot:
        _plot(a.plot, series, f"GenICam pair ({out['mode']}): {out['pair_rate_hz']:.1f} pairs/s, trigger "
                              f"{out['trigger']}, skew basis {out['skew_basis']}")
    if a.json:
        print(json.dumps(out))
    else:
        for k, v in out.items():
            print(f"{k:32s} {v}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
