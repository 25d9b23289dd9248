"""The lab's three computers on one machine, for the namespace tests (test_integration_netns, test_partition).

:func:`three_hosts` creates network namespaces ``<prefix>-{main,arm1,arm2}`` (addresses of
``launch/lab_sim.yaml``) on a bridge inside a fourth ``<prefix>-sw`` namespace; host ``h``'s cable is the veth
:func:`cable` names in the switch namespace, so a test can unplug it (:func:`set_cable`). :class:`HostLaunch`
runs ``flexsheet launch launch/lab_sim.yaml --host NAME`` inside a namespace and collects its output.
Needs root and iproute2 (CI runs as root).
"""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
HOSTS = {"main": "10.77.0.1", "arm1": "10.77.0.2", "arm2": "10.77.0.3"}
PREFIX = f"fs{os.getpid() % 10000}"
KEYS_ROOT = Path("/tmp/flexsheet-test-keys")


def sh(*cmd: str) -> None:
    """Run a command; raise ``CalledProcessError`` (with its output) if it fails."""
    subprocess.run(cmd, check=True, capture_output=True, text=True)


def switch() -> str:
    """Name of the switch namespace."""
    return f"{PREFIX}-sw"


def cable(host: str) -> str:
    """Name of ``host``'s veth end in the switch namespace (its cable to the switch)."""
    return f"{PREFIX}v{list(HOSTS).index(host)}"


def set_cable(host: str, up: bool) -> None:
    """Plug (``up``) or unplug ``host``'s cable at the switch: ``ip link set <veth> up|down``."""
    sh("ip", "netns", "exec", switch(), "ip", "link", "set", cable(host), "up" if up else "down")


def lab_keys() -> Path:
    """CURVE keys for ``launch/lab_sim.yaml`` (CURVE on, as in the lab): generated once per test process into
    a private folder that ``$FLEXSHEET_KEYS`` names for everything started afterwards (the hosts' launchers
    and the tools run in their namespaces). Returns the folder."""
    if not os.environ.get("FLEXSHEET_KEYS", "").startswith(str(KEYS_ROOT)):
        folder = KEYS_ROOT / f"keys-{os.getpid()}"
        subprocess.run([sys.executable, "-m", "flexsheet", "keys", "generate", "--launch",
                        "launch/lab_sim.yaml",
                        "-o", str(folder)], cwd=ROOT, check=True, capture_output=True, text=True)
        os.environ["FLEXSHEET_KEYS"] = str(folder)
    return Path(os.environ["FLEXSHEET_KEYS"])


@contextlib.contextmanager
def three_hosts():
    """Create the namespaces (see module doc); yields host → namespace name; removes them (and kills what
    runs in them) afterwards. Raises ``RuntimeError`` when not root."""
    if os.geteuid() != 0:
        raise RuntimeError("the three-namespace tests need root (CI runs as root)")
    sw = switch()
    names = {h: f"{PREFIX}-{h}" for h in HOSTS}
    lab_keys()
    try:
        sh("ip", "netns", "add", sw)
        sh("ip", "netns", "exec", sw, "ip", "link", "add", "br0", "type", "bridge")
        sh("ip", "netns", "exec", sw, "ip", "link", "set", "br0", "up")
        for host, addr in HOSTS.items():
            ns = names[host]
            sh("ip", "netns", "add", ns)
            sh("ip", "link", "add", cable(host), "netns", sw, "type", "veth", "peer", "name", "eth0", "netns",
               ns)
            sh("ip", "netns", "exec", sw, "ip", "link", "set", cable(host), "master", "br0", "up")
            sh("ip", "netns", "exec", ns, "ip", "addr", "add", f"{addr}/24", "dev", "eth0")
            sh("ip", "netns", "exec", ns, "ip", "link", "set", "eth0", "up")
            sh("ip", "netns", "exec", ns, "ip", "link", "set", "lo", "up")
        yield names
    finally:
        for ns in [*names.values(), sw]:
            out = subprocess.run(["ip", "netns", "pids", ns], capture_output=True, text=True).stdout.split()
            for pid in out:
                try:
                    os.kill(int(pid), signal.SIGKILL)
                except ProcessLookupError:
                    pass
            subprocess.run(["ip", "netns", "del", ns], capture_output=True)


class HostLaunch:
    """``flexsheet launch launch/lab_sim.yaml --host NAME`` inside a namespace; output lines collected with
    their arrival times (``time.time()``)."""

    def __init__(self, ns: str, host: str, *extra: str) -> None:
        self.proc = subprocess.Popen(["ip", "netns", "exec", ns, sys.executable, "-m", "flexsheet", "launch",
                                      "launch/lab_sim.yaml", "--host", host, *extra],
                                     cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        self.lines: list[str] = []
        self.times: list[float] = []
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self) -> None:
        for line in self.proc.stdout:
            self.times.append(time.time())
            self.lines.append(line.rstrip())

    def seen(self, needle: str, after: float = 0.0) -> bool:
        """Whether a line containing ``needle`` arrived after time ``after``."""
        return self.when(needle, after) is not None

    def when(self, needle: str, after: float = 0.0) -> float | None:
        """Arrival time of the first line containing ``needle`` after time ``after``, or None."""
        for t, line in zip(list(self.times), list(self.lines), strict=False):
            if t >= after and needle in line:
                return t
        return None

    def wait(self, needle: str, timeout: float, after: float = 0.0) -> float:
        """Wait for a line containing ``needle`` (after time ``after``); returns its arrival time."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            t = self.when(needle, after)
            if t is not None:
                return t
            time.sleep(0.1)
        raise AssertionError(f"{needle!r} not seen in {timeout} s:\n" + "\n".join(self.lines[-60:]))

    def stop(self) -> None:
        stop_launch(self.proc)


def stop_launch(proc: subprocess.Popen) -> None:
    """Stop a ``flexsheet launch`` process as Ctrl-C does: SIGINT, then SIGKILL after 30 s."""
    if proc.poll() is None:
        proc.send_signal(signal.SIGINT)
        try:
            proc.wait(timeout=30)
        except subprocess.TimeoutExpired:
            proc.kill()



#: one three-host run serves both namespace tests (tests/conftest.py ``lab_run``): the 6 s stroke undisturbed
#: (its Table I row), the 10 s stroke with main's cable to arm1 pulled for CUT_S
#: (test_partition), then arm PC 2 goes away at the 5 s stroke
#: (test_integration_netns). One launch of the three hosts instead of two (~20 s).
LAB_SCRIPT = ("world.script=[{mode: stroke, moving_time: 6}, {mode: stroke, moving_time: 10, seed: 1}, "
              "{mode: stroke, moving_time: 5, seed: 2}]")
CUT_S = 2.0


def run_lab(out: Path) -> dict:
    """The three-host scenario of :data:`LAB_SCRIPT` with ``--out out`` on main. Returns ``main``, ``arm1``,
    ``arm2`` (:class:`HostLaunch`, stopped), ``t_cut``/``t_back``/``t_hold`` (s, ``time.time()``), ``code``
    (main's exit code) and per phase (``loop``, ``cut``, ``arm2_gone``) ``None`` when it went as expected or
    the reason it did not; a failed phase does not stop the later ones (except ``loop``). Raises
    ``RuntimeError`` when the namespaces cannot be made (not root)."""
    r: dict = {"loop": "not run", "cut": "not run", "arm2_gone": "not run", "code": None}
    with three_hosts() as ns:
        arm1 = HostLaunch(ns["arm1"], "arm1")
        arm2 = HostLaunch(ns["arm2"], "arm2")
        main = HostLaunch(ns["main"], "main", "--out", str(out), "--set", LAB_SCRIPT)
        r.update(main=main, arm1=arm1, arm2=arm2)
        try:
            try:
                # the loop closes across hosts: the bridges on arm1/arm2 get targets from the planner on main
                arm1.wait("left arm: ok", 90)
                arm2.wait("right arm: ok", 90)
                r["loop"] = None
            except AssertionError as exc:
                r["loop"] = str(exc)
                return r
            try:
                main.wait("segment 2/3 stroke 10 s: stroke", 120)
                time.sleep(1.0)
                r["t_cut"] = time.time()
                set_cable("arm1", up=False)
                try:
                    time.sleep(CUT_S)
                finally:
                    # taken before the cable goes up: heartbeats queued during the cut flush at once, and main
                    # can print "is back" before `ip link set up`
                    # has returned (CI stop 25 failed on that race)
                    r["t_back"] = time.time()
                    set_cable("arm1", up=True)
                # the arm held: its bridge saw no target for target_timeout and said so
                r["t_hold"] = arm1.wait("left arm: hold:no_target", 10, after=r["t_cut"])
                # main's launcher saw arm1's nodes go silent and come back (after it saw them go)
                t_lost = main.wait("node arm_left on host arm1 lost", 10, after=r["t_cut"])
                main.wait("node arm_left on host arm1 is back", 15, after=max(t_lost, r["t_back"]))
                # the bridge follows targets again
                arm1.wait("left arm: ok", 15, after=r["t_hold"])
                r["cut"] = None
            except (AssertionError, subprocess.CalledProcessError) as exc:
                r["cut"] = str(exc)
            try:
                # at the last stroke, arm PC 2 goes away: main's launcher sees its nodes' heartbeats stop
                main.wait("segment 3/3 stroke 5 s", 120)
                r["t_arm2_gone"] = time.time()
                arm2.proc.send_signal(signal.SIGINT)
                arm2.proc.wait(timeout=30)
                main.wait("node arm_right on host arm2 lost", 15, after=r["t_arm2_gone"])
                r["arm2_gone"] = None
            except (AssertionError, subprocess.TimeoutExpired) as exc:
                r["arm2_gone"] = str(exc)
            try:
                r["code"] = main.proc.wait(timeout=120)
            except subprocess.TimeoutExpired:
                r["code"] = "no exit in 120 s"
        finally:
            for h in (main, arm1, arm2):
                h.stop()
    return r
