"""The live simulated clock (launch files' ``clock: sim``): the discrete-event scheduler of
flexsheet/runtime/lockstep.py in a container of small nodes, and the display's launch run twice."""

from __future__ import annotations

import asyncio
import hashlib
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from flexsheet.runtime.bag_read import read_bag
from flexsheet.runtime.bus import Bus, ContainerTransport
from flexsheet.runtime.clock import SimClock
from flexsheet.runtime.config import NodeConfig
from flexsheet.runtime.container import Container, Member
from flexsheet.runtime.lockstep import SIM_EPOCH
from flexsheet.runtime.node import Node
from flexsheet.runtime.qos import QoS
from messages import FingerTruth
from messages import topics as T

ROOT = Path(__file__).resolve().parents[2]
WORK = T.FINGER_TRUTH.renamed("/work/out")
CHARGED = T.FINGER_TRUTH.renamed("/work/charged")


def _truth(pub, x: float) -> FingerTruth:
    return FingerTruth(header=pub.header("display"), position=np.array([x, 0.0, 0.0]), velocity=np.zeros(3))


class Source(Node):
    """A 10 ms timer whose output leaves 1 ms after each tick (``sim_cost``)."""

    async def setup(self) -> None:
        self.pub = self.publisher(T.FINGER_TRUTH)
        self.n = 0
        self.timer(0.010, self.tick, sim_cost=0.001)

    def tick(self) -> None:
        self.n += 1
        self.pub.publish(_truth(self.pub, float(self.n)))


class Worker(Node):
    """25 ms per input (slower than its 10 ms input, QoS latest); every third input takes 5 ms more."""

    async def setup(self) -> None:
        self.pub = self.publisher(WORK)
        self.charged = self.publisher(CHARGED)
        self.seen = 0
        self.subscribe(T.FINGER_TRUTH, self.on_input, qos=QoS.LATEST, sim_cost=0.025)

    def on_input(self, msg: FingerTruth) -> None:
        self.seen += 1
        if self.seen % 3 == 0:
            self.charge(0.005)
            self.charged.publish(_truth(self.charged, float(msg.position[0])))
        else:
            self.pub.publish(_truth(self.pub, float(msg.position[0])))


class Sink(Node):
    """Keeps (receive time, stamp, value, topic) of everything on the work topics."""

    async def setup(self) -> None:
        self.got: list[tuple[float, float, float, str]] = []
        for topic in (WORK, CHARGED):
            self.subscribe(topic, lambda m, t=topic.name: self.got.append(
                (self.now(), m.header.stamp, float(m.position[0]), t)), qos=QoS.KEEP_ALL)


def _container(until: float, members: list[tuple[type, str]], rtf: float | None = None) -> dict[str, Node]:
    """Run ``members`` (node class, name) in one container on a live simulated clock until ``until`` s past
    the epoch; returns the nodes by name and the bus (key "bus")."""
    async def main() -> dict:
        clock = SimClock(live=True)
        clock.set(SIM_EPOCH)
        bus = Bus("sim", clock=clock)
        made: dict = {"bus": bus}

        def member(cls, name):
            cfg = NodeConfig(name=name, endpoint="", heartbeat_period=0.5)

            def make(b: Bus) -> Node:
                made[name] = cls(cfg, transport=ContainerTransport(b, ""))
                return made[name]
            return Member(name, make)

        c = Container("sim", [member(cls, name) for cls, name in members], bus, sim_until=until, rtf=rtf)
        made["code"] = await asyncio.wait_for(c.run(install_signals=False), timeout=60)
        return made

    return asyncio.run(main())


def _run(until: float, rtf: float | None = None) -> dict:
    made = _container(until, [(Source, "source"), (Worker, "worker"), (Sink, "sink")], rtf)
    return {"code": made["code"], "sink": list(made["sink"].got), "bus": made["bus"],
            "seen": made["worker"].seen}


@pytest.fixture(scope="module")
def run() -> dict:
    return _run(0.2)


def test_outputs_leave_after_the_declared_cost_and_a_busy_node_takes_only_the_newest_input(run):
    assert run["code"] == 0
    got = run["sink"]
    # ticks at epoch + 10 ms·k, each input leaves 1 ms later: the worker's first input is value 1 at +11 ms,
    # handled at once (free), its output leaves 25 ms later
    recv, stamp, value, topic = got[0]
    assert (value, topic) == (1.0, "/work/out")
    assert (stamp == pytest.approx(SIM_EPOCH + 0.011 + 0.025, abs=1e-9)
            and recv == pytest.approx(stamp, abs=1e-9))
    for (_, s0, _, _), (_, s1, v1, t1) in zip(got, got[1:], strict=False):
        busy = 0.025 + (0.005 if t1 == "/work/charged" else 0.0)
        # back to back: never idle, never overlapping
        assert s1 - s0 == pytest.approx(busy, abs=1e-9), (got[:6])
        # the input taken when free is the newest that had left by then (latest QoS): value = ticks so far
        assert v1 == pytest.approx(np.floor((s0 - SIM_EPOCH - 0.001) / 0.010 + 1e-9)), (s0, v1)
    # every third input took 5 ms more (charge): its output leaves 30 ms after the input was taken
    charged = [g for g in got if g[3] == "/work/charged"]
    assert len(charged) == len(got) // 3
    seen = run["seen"]   # one more input may have been taken whose output would leave after the end
    assert len(got) <= seen <= len(got) + 1
    assert run["bus"].lockstep.dropped > 0 and run["bus"].lockstep.charged["worker"] == pytest.approx(
        0.025 * seen + 0.005 * (seen // 3), abs=1e-9)
    assert max(s for _, s, _, _ in got) <= SIM_EPOCH + 0.2 + 1e-9


class DelayedSource(Node):
    """A 10 ms timer, 1 ms of work, its output 35 ms on the link (longer than its period: pipelined)."""

    async def setup(self) -> None:
        self.pub = self.publisher(T.FINGER_TRUTH)
        self.n = 0
        self.ticks: list[float] = []
        self.timer(0.010, self.tick, sim_cost=0.001, sim_delay=0.035)

    def tick(self) -> None:
        self.n += 1
        self.ticks.append(self.now())
        self.pub.publish(_truth(self.pub, float(self.n)))


class TruthSink(Node):
    async def setup(self) -> None:
        self.got: list[tuple[float, float, float]] = []
        self.subscribe(T.FINGER_TRUTH,
                       lambda m: self.got.append((self.now(), m.header.stamp, float(m.position[0]))),
                       qos=QoS.KEEP_ALL)


def test_a_link_delay_is_pipelined_and_never_keeps_its_node_busy():
    """A timer's ``sim_delay`` (the camera link's ``link_delay_s``): each output arrives cost + delay after
    its tick, stamped then, while the ticks go on every period (a busy node would tick every 36 ms)."""
    made = _container(0.2, [(DelayedSource, "source"), (TruthSink, "sink")])
    assert made["code"] == 0
    ticks, got = made["source"].ticks, made["sink"].got
    assert np.allclose(np.diff(ticks), 0.010, atol=1e-9) and len(ticks) >= 19
    assert len(got) == len([t for t in ticks if t + 0.036 <= SIM_EPOCH + 0.2 + 1e-9])
    for recv, stamp, value in got:
        assert (stamp == pytest.approx(ticks[int(value) - 1] + 0.036, abs=1e-9)
                and recv == pytest.approx(stamp))


def test_two_runs_are_identical():
    a, b = _run(0.2)["sink"], _run(0.2)["sink"]
    assert len(a) >= 6 and a == b


def test_a_paced_run_keeps_to_the_wall_clock_and_publishes_the_same():
    """rtf=0.5: 0.4 simulated s take 0.8 wall s (an unpaced run takes a small fraction), same messages."""
    fast = _run(0.4)
    paced = _run(0.4, rtf=0.5)
    st = paced["bus"].lockstep.stats
    assert st.bag_s == pytest.approx(0.4)
    assert st.wall_s == pytest.approx(0.8, rel=0.05) and st.speed == pytest.approx(0.5, rel=0.05)
    assert fast["bus"].lockstep.stats.wall_s < 0.5 * st.wall_s
    assert len(paced["sink"]) >= 12 and paced["sink"] == fast["sink"]


def _hashes(bag: Path) -> dict[str, str]:
    h: dict[str, hashlib._Hash] = {}
    for m in read_bag(bag):
        d = h.setdefault(m.topic, hashlib.sha256())
        for f in m.frames:
            d.update(bytes(f))
    return {k: v.hexdigest() for k, v in h.items()}


def test_the_display_on_the_simulated_clock_is_byte_identical_run_to_run(tmp_path):
    """Two runs of launch/sim.yaml (a 3 s stroke, truth seed 0), the second paced at real speed (--rtf 1),
    write the same messages on every topic but /diagnostics (wall-clock liveness), stamps included; the paced
    one keeps to the wall clock within 5 % where the machine can (the unpaced run faster than real time), else
    it runs as fast as the unpaced one; the summary says the clock."""
    outs = []
    for i in range(2):
        out = tmp_path / f"run{i}"
        res = subprocess.run([sys.executable, "-m", "flexsheet", "launch", "launch/sim.yaml", "--duration",
                              "7",
                              "--out", str(out), "--set", "viz.port=0", "--set", "world.start_delay=1.0",
                              "--set",
                              "world.script=[{mode: stroke, moving_time: 3}]",
                              *(["--rtf", "1"] if i else [])],
                             cwd=ROOT, capture_output=True, text=True, timeout=600)
        assert res.returncode == 0, res.stdout[-4000:] + res.stderr[-2000:]
        outs.append(out)
    h0, h1 = _hashes(outs[0] / "sim.mcap"), _hashes(outs[1] / "sim.mcap")
    topics = set(h0) - {"/diagnostics"}
    assert {"/sheet/target", "/object/deformation", "/fingertip", "/arm/left/joint_state",
            "/render/stereo", "/world/sheet"} <= topics
    assert {t: h0[t] for t in topics} == {t: h1.get(t) for t in topics}
    s = json.loads((outs[0] / "summary.json").read_text())
    assert s["clock"]["kind"] == "sim" and s["realtime_factor"] > 0 and s["seed"] == 0
    assert s["sim_clock"]["sim_s"] == pytest.approx(7.0)
    paced = json.loads((outs[1] / "sim_clock.json").read_text())
    assert s["clock"]["rtf_target"] is None and json.loads((outs[1] / "summary.json").read_text())["clock"][
        "rtf_target"] == 1.0
    # --rtf 1 caps simulated time at the wall clock: never ahead of it; within
    # 5 % of it where this machine runs the graph faster than real time
    # unpaced, else as fast as it can (the unpaced run's factor, within noise)
    unpaced, rtf = s["realtime_factor"], paced["realtime_factor"]
    assert paced["sim_s"] == pytest.approx(7.0) and rtf <= 1.05, (rtf, unpaced)
    if unpaced >= 1.1:
        assert rtf == pytest.approx(1.0, rel=0.05), (rtf, unpaced)
    else:
        assert rtf >= 0.75 * unpaced, (rtf, unpaced)
    chain = s["latency_ms"]["chain"]
    # the chain adds up: each end-to-end figure is the sum of its hops (deterministic costs: medians too)
    assert chain["exposure_to_arm_command"]["median"] == pytest.approx(
        sum(chain[h]["median"] for h in ("exposure_to_camera_frame", "camera_frame_to_fingertip",
                                         "fingertip_to_sheet_target", "sheet_target_to_arm_command")),
        abs=1e-6)
