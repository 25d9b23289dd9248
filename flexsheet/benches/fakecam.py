"""Two Aravis fake GigE Vision cameras (``arv-fake-gv-camera-0.8``, Debian ``aravis-tools``) on loopback.

The fake camera serves the real GVCP (control, UDP 3956) and GVSP (stream) protocols, so everything
between Aravis and our pairing code runs as with a real GigE camera. Two of them need two IPv4 addresses:
``-i`` takes an interface name or an address *assigned to an interface* (it looks the address up in the
interface list), and GVCP's port 3956 can be bound once per address. Linux routes all of 127/8 to ``lo``,
but only 127.0.0.1 is assigned there, so ``-i 127.0.0.2`` fails with "No network interface with address
or name '127.0.0.2' found". :func:`isolated` therefore runs a command in a private network namespace
(``unshare -n`` as root, ``unshare -rn`` — a user namespace — otherwise) whose ``lo`` also carries
127.0.0.2; nothing on the host's network changes. :func:`fake_pair` starts the two cameras there.

Fake camera facts that matter for the numbers (Aravis 0.8.26 ``arvfakecamera.c``/``arvgvfakecamera.c``):
frames are stamped with the host's real-time clock (``g_get_real_time``, µs resolution), so the two fake
cameras share one device clock; in free run both start frames on the same grid (``now mod period``), which
makes the pair behave like a PTP-synchronised synchronous free run; a software trigger is served only at
the camera's next 25 Hz tick, so triggered pairs can be 40 ms apart (use free run with fake cameras);
``-r`` drops GVSP packets (per thousand) to exercise the drop counters.

Not the camera node's device I/O: the cameras are simulated devices that the camera bench and the GenICam
tests start; whether Aravis sees them is asked of the stereo camera port's ``genicam`` source
(:mod:`flexsheet.vision.camera_port`, its ``probe``), as ``flexsheet launch --check --probe`` asks it.
"""

from __future__ import annotations

import contextlib
import ctypes
import os
import shutil
import signal
import subprocess
import time
from types import SimpleNamespace

from flexsheet.vision.camera_port import camera_source

__all__ = ["FAKE_CAMERA", "ADDRESSES", "ENV_FLAG", "isolated", "addresses_ready", "fake_pair"]

FAKE_CAMERA = "arv-fake-gv-camera-0.8"
ADDRESSES = ("127.0.0.1", "127.0.0.2")
ENV_FLAG = "FLEXSHEET_FAKECAM_NETNS"


def _die_with_parent() -> None:  # pragma: no cover - runs in the forked child
    """prctl(PR_SET_PDEATHSIG, SIGTERM): a fake camera ends when the process that started it dies, even by
    SIGKILL (otherwise it would keep a private network namespace alive)."""
    try:
        ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGTERM, 0, 0, 0)
    except (OSError, AttributeError):
        pass


def addresses_ready(addresses=ADDRESSES) -> bool:
    """True when every address in ``addresses`` is assigned to an interface here (``ip -4 -o addr``)."""
    try:
        out = subprocess.run(["ip", "-4", "-o", "addr", "show"], capture_output=True, text=True,
                             timeout=5).stdout
    except (OSError, subprocess.TimeoutExpired):
        return False
    have = {tok.split("/")[0] for line in out.splitlines() for i, tok in enumerate(line.split())
            if i > 0 and line.split()[i - 1] == "inet"}
    return all(a in have for a in addresses)


def isolated(cmd: list[str]) -> list[str]:
    """``cmd`` wrapped to run in a private network namespace with ``lo`` up carrying 127.0.0.1 and
    127.0.0.2 (module doc). Raises ``RuntimeError`` naming what is missing when neither ``unshare -n``
    nor ``unshare -rn`` works here (then: run as root, or enable unprivileged user namespaces)."""
    for tool in ("unshare", "ip"):
        if shutil.which(tool) is None:
            raise RuntimeError(f"{tool!r} not found (Debian util-linux / iproute2)")
    tried = []
    for flags in (["-n"], ["-rn"]) if os.geteuid() == 0 else (["-rn"],):
        probe = subprocess.run(["unshare", *flags, "true"], capture_output=True, text=True)
        if probe.returncode == 0:
            script = f"ip link set lo up && ip addr add {ADDRESSES[1]}/8 dev lo && exec \"$@\""
            return ["env", f"{ENV_FLAG}=1", "unshare", *flags, "sh", "-c", script, "sh", *cmd]
        tried.append(f"unshare {' '.join(flags)}: {probe.stderr.strip() or probe.returncode}")
    raise RuntimeError("cannot create a private network namespace for the fake cameras (" + "; ".join(tried)
                       + "): run as root or enable unprivileged user namespaces "
                         "(sysctl kernel.unprivileged_userns_clone=1)")


@contextlib.contextmanager
def fake_pair(serials=("FSLEFT01", "FSRIGHT01"), addresses=ADDRESSES, lost_permille=(0, 0),
              timeout_s: float = 10.0):
    """Start two fake cameras (serials on ``addresses``; ``lost_permille``: GVSP packets dropped per
    thousand, per camera) and wait until Aravis discovers both (the ``genicam`` source's probe finds both
    serials); yields the serials. Stops both on exit. Raises ``RuntimeError`` with the cameras' output when
    they do not come up (the usual cause: an address not assigned to an interface here — use
    :func:`isolated`)."""
    if shutil.which(FAKE_CAMERA) is None:
        raise RuntimeError(f"{FAKE_CAMERA} not found: apt install aravis-tools")
    procs = []
    try:
        for serial, addr, lost in zip(serials, addresses, lost_permille, strict=True):
            cmd = [FAKE_CAMERA, "-i", addr, "-s", serial]
            if lost:
                cmd += ["-r", str(int(lost))]
            procs.append(subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                                          preexec_fn=_die_with_parent))
        deadline = time.monotonic() + timeout_s
        genicam = camera_source("genicam")
        missing: list[str] = []
        while time.monotonic() < deadline:
            dead = [p for p in procs if p.poll() is not None]
            if dead:
                out = " | ".join((p.stdout.read() or "").strip() for p in dead)
                raise RuntimeError(f"fake camera exited ({' '.join(dead[0].args)}): {out}")
            missing = genicam.probe(SimpleNamespace(left_id=serials[0], right_id=serials[1]))
            if not missing:
                break
            time.sleep(0.2)
        else:
            raise RuntimeError(f"fake cameras {serials} on {addresses} not discovered in {timeout_s} s: "
                               + "; ".join(missing))
        yield list(serials)
    finally:
        for p in procs:
            if p.poll() is None:
                p.terminate()
        for p in procs:
            try:
                p.wait(timeout=3)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait(timeout=3)
            if p.stdout:
                p.stdout.close()
