"""Arm bridge ↔ controller twin over MELFA real-time external control (MXT, UDP on 127.0.0.1), and the twin's
MXT logic (refusals, no-packet timeout: hold or fault).

The twin runs in its own thread and event loop (a stalled bridge loop does not stall the controller, as on
the real system); the bridge runs in the test's loop through :class:`NodeHarness`.
"""

from __future__ import annotations

import asyncio
import threading
import time

import numpy as np
import pytest
from test_arm_bridge import clamp_pose, target

from flexsheet.arm.kinematics import Q_HOME, Q_UPPER, QD_MAX, home_joints
from flexsheet.runtime.testing import NodeHarness
from flexsheet.twin.mxt_server import MxtCore, MxtTwin
from flexsheet.twin.servo import ServoParams
from messages import mxt, topics
from nodes.arm_bridge.node import ArmBridgeNode

T = 0.00711


class ThreadTwin:
    """An :class:`MxtTwin` serving from its own thread; ``drop`` (callable(kind, n) -> bool) can drop the n-th
    request ("request") or reply ("reply") to fake a lost datagram."""

    def __init__(self, q0=None, speed_scale: float = 1.0, drop=None, **core_kw) -> None:
        sp = ServoParams()
        servo = ServoParams(qd_max=sp.qd_max * speed_scale, qdd_max=sp.qdd_max * speed_scale)
        self.core = MxtCore(home_joints("left") if q0 is None else q0, period=T, servo=servo,
                            now=time.monotonic(), **core_kw)
        self.core.command_log = []
        self.drop = drop
        self.port = None
        self._ready = threading.Event()
        self._stop: asyncio.Event | None = None
        self._thread = threading.Thread(target=lambda: asyncio.run(self._main()), daemon=True)

    async def _main(self) -> None:
        twin = MxtTwin(self.core, "127.0.0.1", 0)
        if self.drop is not None:
            counts = {"request": 0, "reply": 0}
            on_datagram, transport_holder = twin._on_datagram, {}

            def filtered(data, addr):
                counts["request"] += 1
                if not self.drop("request", counts["request"]):
                    on_datagram(data, addr)
            twin._on_datagram = filtered
            await twin.start()
            real_sendto = twin.transport.sendto

            def sendto(data, addr):
                counts["reply"] += 1
                if not self.drop("reply", counts["reply"]):
                    real_sendto(data, addr)
            transport_holder["t"] = twin.transport
            twin.transport.sendto = sendto
        else:
            await twin.start()
        self.port = twin.port
        self._stop = asyncio.Event()
        self._loop = asyncio.get_running_loop()
        self._ready.set()
        await self._stop.wait()
        await twin.stop()

    def __enter__(self) -> ThreadTwin:
        self._thread.start()
        assert self._ready.wait(10)
        return self

    def __exit__(self, *exc) -> None:
        self._loop.call_soon_threadsafe(self._stop.set)
        self._thread.join(5)


def _bridge_params(port, **kw):
    return {"arm": "left", "protocol": "mxt", "port": port, "target_timeout": 2.0, **kw}


def _executed_steps(core) -> np.ndarray:
    log = np.array(core.command_log)
    return np.abs(np.diff(log, axis=0))


def test_bridge_follows_a_target_over_mxt_and_end_stops_the_session():
    async def scenario(twin):
        async with NodeHarness(ArmBridgeNode, params=_bridge_params(twin.port), name="mxt_left") as h:
            for k in range(60):                             # ramp to -0.39 rad, then keep sending it
                h.inject(topics.ARM_LEFT_TARGET, target("left", -0.01 * min(k, 39), stamp=float(k)))
                await asyncio.sleep(0.02)
            states = h.messages(topics.ARM_LEFT_STATE)
            link = h.node.link.counters()
            assert twin.core.session == "open" and twin.core.sessions == 1
        return states, link

    with ThreadTwin() as twin:
        states, link = asyncio.run(scenario(twin))
        time.sleep(0.3)                                     # END sent at teardown; the arm settles
        core = twin.core
        assert core.ends == 1 and core.session == "idle"
        q_end = core.servo.q.copy()
        time.sleep(0.1)
        assert np.max(np.abs(core.servo.q - q_end)) < 1e-9   # stopped: holds the last command
        assert np.max(np.abs(core.servo.q - core.active)) < 1e-5
    last = states[-1]
    assert last.bridge_status == "ok" and last.target_stamp == 59.0
    want = clamp_pose("left", -0.39)
    assert np.linalg.norm(last.pose[:3, 3] - want[:3, 3]) < 1e-4            # FB_JOINT → FK at the target
    assert np.allclose(last.pose[:3, :3], want[:3, :3], atol=1e-4)
    assert np.max(np.abs(last.position - last.commanded)) < 1e-4
    assert core.refused == 0 and core.moves > 100
    # one MOVE per controller cycle: the bridge is paced by the replies
    assert link["replies"] >= 0.97 * link["sent"] and link["refused"] == 0
    steps = np.abs(np.diff(np.array([m.commanded for m in states]), axis=0))
    assert np.all(steps <= 0.5 * QD_MAX * T * (1 + 1e-6))
    # measured (FB_JOINT) lags the command during the move: the twin's servo, not an echo of the command
    assert max(np.max(np.abs(m.position - m.commanded)) for m in states) > 1e-3


def _cruise(twin, stall_at: float | None = None):
    """Drive the bridge toward a far target at a low, saturated speed (every step = qd·T on J6)."""
    async def scenario():
        params = _bridge_params(twin.port, speed_scale=0.03, accel_scale=100.0)
        async with NodeHarness(ArmBridgeNode, params=params, name="mxt_cruise") as h:
            h.inject(topics.ARM_LEFT_TARGET, target("left", 0.0, stamp=1.0))
            await asyncio.sleep(0.3)
            h.inject(topics.ARM_LEFT_TARGET, target("left", 0.35, stamp=2.0))
            t0, stall = time.monotonic(), stall_at
            while time.monotonic() - t0 < 1.2:
                if stall is not None and time.monotonic() - t0 > stall:
                    time.sleep(0.06)                         # the bridge's loop misses ~8 controller cycles
                    stall = None
                await asyncio.sleep(0.01)
            return h.messages(topics.ARM_LEFT_STATE), h.node.link.counters()
    return asyncio.run(scenario())


@pytest.mark.parametrize("case", ["stall", "lost_request", "lost_reply"])
def test_a_missed_cycle_never_makes_the_controller_jump(case):
    qd_T = 0.03 * QD_MAX * T
    drop = {"stall": None,
            "lost_request": lambda kind, n: kind == "request" and n in (75, 76),
            "lost_reply": lambda kind, n: kind == "reply" and n in (75, 76)}[case]
    with ThreadTwin(drop=drop) as twin:
        states, link = _cruise(twin, stall_at=0.3 if case == "stall" else None)
        steps = _executed_steps(twin.core)
    assert twin.core.refused == 0
    cruise = steps[:, 5] > 0.9 * qd_T[5]
    assert cruise.sum() > 40                                 # J6 cruised at the speed limit
    # the command the controller executes never steps more than one cycle's worth (a jump would be 2·qd·T)
    assert np.all(steps <= qd_T * (1 + 1e-4) + 2e-7), np.max(steps / qd_T, axis=0)
    if case == "stall":
        held = np.flatnonzero(steps.max(axis=1) == 0.0)
        assert len(held) >= 4                                 # the controller saw cycles without a packet
    else:
        assert link["repeats"] >= 1 and link["lost"] + link["late"] >= 1
    assert states[-1].bridge_status == "ok"


def test_bridge_restarts_from_what_the_controller_executes_when_it_refuses_steps():
    # the controller's speed limit is below the bridge's: the bridge's cruising steps get refused
    with ThreadTwin(speed_scale=0.05) as twin:
        async def scenario():
            async with NodeHarness(ArmBridgeNode, params=_bridge_params(twin.port), name="mxt_ref") as h:
                for k in range(150):
                    h.inject(topics.ARM_LEFT_TARGET, target("left", 0.3, stamp=float(k)))
                    await asyncio.sleep(0.02)
                return h.messages(topics.ARM_LEFT_STATE), h.node.link.counters()
        states, link = asyncio.run(scenario())
        steps = _executed_steps(twin.core)
        cap = 0.05 * QD_MAX * T * 1.5
    assert twin.core.refused >= 1 and link["refused"] >= 1
    assert "hold:refused" in {m.bridge_status for m in states}
    assert np.all(steps <= cap + 1e-6)                        # nothing beyond the controller's limit ran
    want = clamp_pose("left", 0.3)
    assert np.linalg.norm(states[-1].pose[:3, 3] - want[:3, 3]) < 1e-4   # and the arm still got there


def test_bridge_reopens_after_a_no_packet_fault():
    with ThreadTwin(timeout=0.05, on_timeout="fault") as twin:
        async def scenario():
            params = _bridge_params(twin.port, mxt_lost_cycles=10, backoff_min=0.02)
            async with NodeHarness(ArmBridgeNode, params=params, name="mxt_fault") as h:
                h.inject(topics.ARM_LEFT_TARGET, target("left", 0.0, stamp=1.0))
                await asyncio.sleep(0.2)
                h.inject(topics.ARM_LEFT_TARGET, target("left", 0.2, stamp=2.0))
                await asyncio.sleep(0.05)
                time.sleep(0.12)                              # bridge silent > timeout: the controller faults
                for k in range(40):
                    h.inject(topics.ARM_LEFT_TARGET, target("left", 0.2, stamp=3.0 + k))
                    await asyncio.sleep(0.02)
                # the twin's counts while the bridge still streams: the harness's teardown may leave the twin
                # silent past its 50 ms timeout before it stops (a trailing fault, seen once in a full suite)
                core = twin.core
                return (h.messages(topics.ARM_LEFT_STATE), h.node.link.counters(),
                        (core.faults, core.sessions, core.unanswered, core.refused))
        states, link, (faults, sessions, unanswered, refused) = asyncio.run(scenario())
    # one fault is provoked; a loaded machine can stall the bridge past the 50 ms timeout once more (seen once
    # in a full-suite run): every fault must still be followed by a reopened session
    assert faults >= 1 and sessions == faults + 1 and unanswered >= 1
    assert link["opens"] == sessions
    assert refused == 0                                       # the restart streamed from the fault pose
    assert states[-1].bridge_status == "ok"
    want = clamp_pose("left", 0.2)
    assert np.linalg.norm(states[-1].pose[:3, 3] - want[:3, 3]) < 1e-4


# ------------------------------------------------------------------------------------- twin logic (pure)
def _open(core, now=0.0):
    assert core.receive(mxt.null_packet(0), now) is not None
    return core


def test_twin_refuses_oversize_steps_limits_and_non_joint_commands():
    core = _open(MxtCore(Q_HOME, period=T))
    cap = QD_MAX * T * 1.5
    ok = Q_HOME + 0.9 * cap
    joint = core.receive(mxt.move_packet(ok, 1), 0.001)
    assert np.allclose(joint, ok.astype(np.float32), atol=1e-6) and core.refused == 0
    bad = [
        ok + np.array([0, 0, 0, 0, 0, 1.2 * cap[5]]),                        # step beyond the speed limit
        np.where(np.arange(6) == 2, Q_UPPER[2] + 0.01, ok),                   # J3 beyond its limit
    ]
    for k, q in enumerate(bad):
        joint = core.receive(mxt.move_packet(q, 2 + k), 0.002)
        assert np.allclose(joint, ok, atol=1e-6)                             # JOINT: still the old command
    pose = mxt.Packet(mxt.CMD_MOVE, mxt.TYP_POSE, (mxt.TYP_JOINT, 0, 0, 0), ccount=9)
    core.receive(pose, 0.003)
    assert core.refused == 3 and "not JOINT" in core.last_refusal
    rep = mxt.Packet.decode(
        core.reply(mxt.move_packet(bad[0], 2, (mxt.TYP_FB_JOINT, mxt.TYP_POSE, 0, 0))).encode())
    assert rep.recv_types == (mxt.TYP_FB_JOINT, mxt.TYP_NULL, 0, 0) and rep.ccount == 2   # unmodelled → NULL
    assert np.allclose(rep.joints(mxt.TYP_FB_JOINT), Q_HOME, atol=1e-6)


def test_twin_no_packet_timeout_holds_or_faults():
    cap = QD_MAX * T * 1.5
    for action in ("hold", "fault"):
        core = _open(MxtCore(Q_HOME, period=T, timeout=0.02, on_timeout=action))
        t = 0.0
        for k in range(1, 13):                               # a ramp faster than the servo can follow
            q_last = Q_HOME + k * 0.8 * cap
            assert core.receive(mxt.move_packet(q_last, k), t) is not None
            t += T
            core.advance(t)
        assert core.refused == 0 and np.max(np.abs(core.servo.q - q_last)) > 0.05   # the servo lags
        for t_k in np.arange(t, 1.5, T):                     # then no packets at all
            core.advance(t_k)
        t = 1.5
        assert core.timeouts == 1
        if action == "hold":                                 # keeps servoing to the last command
            assert core.missed_cycles > 150                  # TCount keeps counting silent cycles
            assert core.session == "open" and np.max(np.abs(core.servo.q - q_last)) < 1e-4
            assert core.receive(mxt.move_packet(q_last, 13), t) is not None          # packets resume
        else:                                                # stops short, session over
            assert core.session == "fault" and np.max(np.abs(core.servo.q - q_last)) > 0.05
            assert np.max(np.abs(core.servo.v)) < 1e-9
            assert core.receive(mxt.move_packet(q_last, 13), t) is None              # MOVE unanswered
            assert core.receive(mxt.null_packet(0), t) is not None and core.session == "open"
            assert np.allclose(core.active, core.servo.q)    # a new session starts where the arm stopped


def test_twin_ends_on_end_and_answers_nothing_but_null_outside_a_session():
    core = MxtCore(Q_HOME, period=T)
    assert core.receive(mxt.move_packet(Q_HOME, 1), 0.0) is None and core.unanswered == 1
    _open(core)
    assert core.receive(mxt.end_packet(2), 0.01) is not None
    assert core.session == "idle" and core.ends == 1
    assert core.receive(mxt.move_packet(Q_HOME, 3), 0.02) is None


def test_disabled_bridge_exchanges_null_packets_and_commands_nothing():
    with ThreadTwin() as twin:
        async def scenario():
            params = _bridge_params(twin.port, enabled=False)
            async with NodeHarness(ArmBridgeNode, params=params, name="mxt_off") as h:
                for k in range(20):
                    h.inject(topics.ARM_LEFT_TARGET, target("left", 0.2, stamp=float(k)))
                    await asyncio.sleep(0.02)
                return h.messages(topics.ARM_LEFT_STATE)
        states = asyncio.run(scenario())
        core = twin.core
    assert len(states) > 20 and {m.bridge_status for m in states} == {"hold:disabled"}
    assert core.moves == 0 and core.received > 20 and core.refused == 0
    assert np.max(np.abs(core.servo.q - home_joints("left"))) < 1e-9          # the arm never moved
    assert np.max(np.abs(states[-1].position - home_joints("left"))) < 1e-6   # and its joints are reported
