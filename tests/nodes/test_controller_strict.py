"""The controller twin is as strict as a real controller, the links and the planner hold against hostile
input, every rejection is counted, and ``--check`` refuses absurd safety params.

* one command per control cycle (the newest of the cycle), each step checked against the command executed in
  the previous cycle: a burst of 60 MXT MOVEs or 20 Modbus target writes in one cycle moves the executed
  command by at most one step; the extras are counted;
* the MXT session belongs to the address and port that opened it; CCount must increase;
* a Modbus e-stop latches until the twin's local reset; a watchdog fault until an explicit RESET;
* the planner refuses a fingertip from the future alone and survives a backward clock step;
* ``flexsheet launch FILE --check`` names an out-of-range param and its value.

Counts are printed (``pytest -s``); no assertion depends on timing.
"""

from __future__ import annotations

import asyncio
import logging
import math
import time

import numpy as np
import pytest
from pymodbus.client import AsyncModbusTcpClient
from test_arm_bridge import read_state, start_twin, target

from flexsheet.arm.kinematics import Q_HOME, Q_LOWER, Q_UPPER, QD_MAX, ArmKinematics, home_joints
from flexsheet.arm.tracking import TargetRefused, TargetTracker
from flexsheet.model.geometry import LEFT_BASE
from flexsheet.model.shapes import make_shape
from flexsheet.planning.plan import Hold
from flexsheet.planning.planner_config import PlannerConfig
from flexsheet.planning.surface_planner import SurfacePlanner
from flexsheet.runtime.config import ConfigError
from flexsheet.runtime.launch_check import check_launch
from flexsheet.runtime.testing import NodeHarness
from flexsheet.twin.controller import ControllerCore, WriteRejected
from flexsheet.twin.modbus_server import ControllerTwin
from flexsheet.twin.mxt_server import MxtCore, MxtTwin
from messages import ArmTarget, Fingertip, Header, mxt, topics
from messages import registers as reg
from nodes.arm_bridge.node import ArmBridgeNode
from nodes.planner.node import PlannerNode

T_MXT = 0.00711
T_MB = 0.0071
CAP_MXT = QD_MAX * T_MXT * 1.5          # the twins' default step check (step_tolerance 1.5)
CAP_MB = QD_MAX * T_MB * 1.5
OWNER, STRANGER = ("127.0.0.1", 40001), ("127.0.0.1", 40002)


# ----------------------------------------------------------------------------------------- MXT: one per cycle
def _mxt_open(now=0.0, addr=OWNER, **kw):
    core = MxtCore(Q_HOME, period=T_MXT, now=0.0, **kw)
    core.command_log = []
    assert core.receive(mxt.null_packet(0), now, addr) is not None
    return core


def test_mxt_60_moves_in_one_cycle_execute_one_step():
    """The finding: 60 MOVEs of +0.02 rad each (J1) inside one 7.11 ms cycle moved the executed J1 by 1.2 rad
    (each checked against the previous packet). Now each is checked against the command executed in the
    previous cycle and one command runs per cycle."""
    core = _mxt_open(0.001)                             # the session opened in cycle 0
    for k in range(1, 61):                              # 60 MOVEs inside cycle 1
        q = Q_HOME.copy()
        q[0] += 0.02 * k
        core.receive(mxt.move_packet(q, k), T_MXT + 0.001 + 1e-5 * k, OWNER)
    core.advance(2 * T_MXT + 1e-6)                      # the cycle boundary executes one command
    moved = abs(core.active[0] - Q_HOME[0])
    print(f"\n[strict] mxt ramp burst: executed J1 step {moved:.4f} rad (cap {CAP_MXT[0]:.4f}); moves "
          f"{core.moves}, refused {core.refused}, extra {core.extra}")
    assert moved <= CAP_MXT[0] + 1e-6 and moved == pytest.approx(0.02, abs=1e-6)
    assert core.extra == 59 and core.refused == 59 and core.moves == 1
    # and a burst of 60 valid MOVEs (each within one step of the executed command): the newest runs
    core = _mxt_open(0.001)
    qs = []
    for k in range(1, 61):
        q = Q_HOME + (0.9 if k % 2 else -0.9) * CAP_MXT * (k / 60.0)
        qs.append(q)
        core.receive(mxt.move_packet(q, k), T_MXT + 0.001 + 1e-5 * k, OWNER)
    core.advance(2 * T_MXT + 1e-6)
    print(f"[strict] mxt valid burst: superseded {core.superseded}, extra {core.extra}, executed "
          f"{core.executed}")
    assert core.extra == 59 and core.superseded == 59 and core.executed == 1 and core.refused == 0
    assert np.allclose(core.active, qs[-1].astype(np.float32), atol=1e-6)
    assert np.all(np.abs(core.active - Q_HOME) <= CAP_MXT + 1e-6)


def test_mxt_flood_over_udp_never_executes_more_than_one_step_per_cycle():
    """60 MOVEs sent back to back over UDP, a ramp of 0.02 rad per packet (1.2 rad in all): whatever cycles
    they land in, no executed step exceeds the check, and the total motion is bounded by the cycles."""
    async def scenario():
        core = MxtCore(Q_HOME, period=T_MXT, now=time.monotonic())
        core.command_log = []
        twin = MxtTwin(core, "127.0.0.1", 0)
        await twin.start()
        client = await _UdpClient.open(twin.port)
        try:
            client.send(mxt.null_packet(0))
            await client.wait(1)
            n0 = len(core.command_log)
            for k in range(1, 61):
                q = Q_HOME.copy()
                q[0] += 0.02 * k
                client.send(mxt.move_packet(q, k))
            await asyncio.sleep(0.1)
            return core, np.array(core.command_log[max(0, n0 - 1):])
        finally:
            client.close()
            await twin.stop()

    core, log = asyncio.run(scenario())
    steps = np.abs(np.diff(log, axis=0))
    total = abs(log[-1][0] - Q_HOME[0])
    print(f"\n[strict] mxt udp flood: executed J1 {total:.4f} rad over {len(log)} cycles, largest step "
          f"{steps[:, 0].max():.4f} (cap {CAP_MXT[0]:.4f}); moves {core.moves}, refused {core.refused}, "
          f"extra {core.extra}, superseded {core.superseded}")
    assert np.all(steps <= CAP_MXT + 1e-6)
    assert core.moves + core.refused == 60 and core.refused >= 1
    assert total <= 0.02 * core.moves + 1e-6 < 1.2


# ------------------------------------------------------------------------------------ MXT: owner and CCount
def test_a_strangers_end_leaves_the_owners_session_open():
    core = _mxt_open()
    assert core.receive(mxt.end_packet(1), 0.001, STRANGER) is None          # another source port
    assert core.session == "open" and core.owner == OWNER and core.foreign == 1 and core.ends == 0
    assert core.receive(mxt.null_packet(0), 0.002, STRANGER) is None         # cannot take an active session
    q = Q_HOME + 0.5 * CAP_MXT
    assert core.receive(mxt.move_packet(q, 1), 0.003, OWNER) is not None     # the owner still streams
    assert core.receive(mxt.end_packet(2), 0.004, OWNER) is not None and core.session == "idle"
    assert core.foreign == 2 and core.ends == 1
    # a silent owner's session is taken over by a new sender's NULL (a respawned bridge on a new port)
    core = _mxt_open(owner_timeout=0.2)
    assert core.receive(mxt.null_packet(0), 0.1, STRANGER) is None
    assert core.receive(mxt.null_packet(7), 0.5, STRANGER) is not None
    assert core.owner == STRANGER and core.takeovers == 1 and core.sessions == 2


def test_a_strangers_end_over_udp_leaves_the_owners_session_open():
    async def scenario():
        core = MxtCore(Q_HOME, period=T_MXT, now=time.monotonic())
        twin = MxtTwin(core, "127.0.0.1", 0)
        await twin.start()
        owner, stranger = await _UdpClient.open(twin.port), await _UdpClient.open(twin.port)
        try:
            owner.send(mxt.null_packet(0))
            await owner.wait(1)
            stranger.send(mxt.end_packet(1))                  # a different UDP source port
            await asyncio.sleep(0.05)
            owner.send(mxt.move_packet(Q_HOME + 0.5 * CAP_MXT, 1))
            await owner.wait(2)
            return core, len(stranger.replies), owner.replies
        finally:
            owner.close()
            stranger.close()
            await twin.stop()

    core, stranger_replies, replies = asyncio.run(scenario())
    print(f"\n[strict] stranger END: session {core.session}, foreign {core.foreign}, ends {core.ends}")
    assert core.session == "open" and core.ends == 0 and core.foreign == 1 and stranger_replies == 0
    assert replies[-1].command == mxt.CMD_MOVE and replies[-1].ccount == 1


def test_replayed_and_out_of_order_ccounts_are_dropped_and_counted():
    core = _mxt_open()
    q5 = Q_HOME + 0.5 * CAP_MXT
    assert core.receive(mxt.move_packet(q5, 5), 0.001, OWNER) is not None
    assert core.receive(mxt.move_packet(q5, 5), 0.002, OWNER) is None        # replayed
    assert core.receive(mxt.move_packet(Q_HOME, 3), 0.003, OWNER) is None    # out of order
    assert core.receive(mxt.end_packet(4), 0.004, OWNER) is None             # an old END is no END either
    assert core.replayed == 3 and core.session == "open" and core.moves == 1
    assert core.receive(mxt.move_packet(q5, 6), 0.005, OWNER) is not None
    core2 = MxtCore(Q_HOME, period=T_MXT)                # serial-number order: the counter may wrap
    assert core2.receive(mxt.null_packet(0xFFFFFFFE), 0.0, OWNER) is not None
    assert core2.receive(mxt.move_packet(Q_HOME, 0xFFFFFFFF), 0.001, OWNER) is not None
    assert core2.receive(mxt.move_packet(Q_HOME, 0), 0.002, OWNER) is not None and core2.replayed == 0
    print(f"\n[strict] ccount: replayed/out-of-order dropped {core.replayed}")


def test_the_bridge_reopens_its_own_session_with_an_increasing_ccount():
    """Replies lost for a while: the bridge reopens with NULL on the same socket while the twin's session is
    still open; its CCount goes on increasing, so the twin takes it (a CCount restarting at 0 would be dropped
    as a replay and the bridge locked out)."""
    from test_arm_mxt import ThreadTwin, _bridge_params

    with ThreadTwin(drop=lambda kind, n: kind == "reply" and 40 <= n < 52) as twin:
        async def scenario():
            params = _bridge_params(twin.port, mxt_lost_cycles=10, backoff_min=0.02)
            async with NodeHarness(ArmBridgeNode, params=params, name="mxt_reopen") as h:
                for k in range(60):
                    h.inject(topics.ARM_LEFT_TARGET, target("left", 0.1, stamp=float(k)))
                    await asyncio.sleep(0.02)
                return h.messages(topics.ARM_LEFT_STATE), h.node.link.counters()
        states, link = asyncio.run(scenario())
        core = twin.core
    print(f"\n[strict] bridge reopen: opens {link['opens']}, twin sessions {core.sessions}, replayed "
          f"{core.replayed}, foreign {core.foreign}")
    assert link["opens"] >= 2 and core.sessions == 1 and core.replayed == 0 and core.foreign == 0
    assert states[-1].bridge_status == "ok"


# --------------------------------------------------------------------------------- Modbus: one per period
def _mb_enabled():
    core = ControllerCore(Q_HOME, period=T_MB, now=0.0)
    core.write_holding(reg.HR_COMMAND, [reg.CMD_ENABLE], 0.0)
    core.command_log = []
    return core


def test_modbus_20_target_writes_in_one_period_execute_one_step():
    core = _mb_enabled()
    q = Q_HOME.copy()
    refused = 0
    for k in range(20):  # each 0.9 cap beyond the last write: the finding's ramp
        q = q + 0.9 * CAP_MB
        try:
            core.write_holding(reg.HR_WATCHDOG, [k + 1, *reg.encode_joints(q)], 1e-4 * (k + 1))
        except WriteRejected as exc:
            assert exc.code == reg.REJ_TARGET_STEP
            refused += 1
    core.advance(T_MB + 1e-6)
    step = np.abs(core.active - Q_HOME) / CAP_MB
    print(f"\n[strict] modbus ramp burst: executed step {step.max():.3f} x cap; refused {refused} of 20")
    assert step.max() <= 1.0 + 1e-6 and refused == 19
    core = _mb_enabled()                                 # 20 valid writes: the newest runs, 19 superseded
    for k in range(20):
        q = Q_HOME + (0.9 if k % 2 else -0.9) * CAP_MB
        core.write_holding(reg.HR_WATCHDOG, [k + 1, *reg.encode_joints(q)], 1e-4 * (k + 1))
    core.advance(T_MB + 1e-6)
    print(f"[strict] modbus valid burst: superseded {core.superseded}, executed {core.executed}")
    assert core.superseded == 19 and core.executed == 1
    assert np.allclose(core.active, q, atol=2e-6)


def test_modbus_write_flood_over_tcp_never_executes_more_than_one_step_per_period():
    async def scenario():
        # a long watchdog: a scheduling stall of the test must not trip it mid-flood
        # (a trip holds the arm where it measures, which is not a commanded step)
        core = ControllerCore(home_joints("left"), watchdog_periods=100, now=time.monotonic())
        twin = ControllerTwin(core, "127.0.0.1", 0)
        await twin.start()
        twin.core.command_log = []
        client = AsyncModbusTcpClient("127.0.0.1", port=twin.port, timeout=1.0, retries=0, reconnect_delay=0)
        assert await client.connect()
        try:
            await client.write_register(reg.HR_COMMAND, reg.CMD_ENABLE, device_id=1)
            q = (await read_state(client)).position
            n0, errors = len(twin.core.command_log), 0
            for k in range(20):                          # as fast as the socket goes
                q = q + 0.9 * CAP_MB
                rr = await client.write_registers(reg.HR_WATCHDOG, [k + 1, *reg.encode_joints(q)],
                                                  device_id=1)
                errors += rr.isError()
            await asyncio.sleep(0.05)
            return twin.core, np.array(twin.core.command_log[max(0, n0 - 1):]), errors
        finally:
            client.close()
            await twin.stop()

    core, log, errors = asyncio.run(scenario())
    steps = np.abs(np.diff(log, axis=0)) / CAP_MB
    print(f"\n[strict] modbus tcp flood: largest executed step {steps.max():.3f} x cap over {len(log)} "
          f"periods; refused {errors} of 20")
    assert np.all(steps <= 1.0 + 1e-6)


# ----------------------------------------------------------------------------------- Modbus: e-stop, watchdog
def test_modbus_reset_does_not_clear_an_estop_the_local_reset_does(tmp_path):
    reset_file = tmp_path / "reset"

    async def scenario():
        core = ControllerCore(home_joints("left"), now=time.monotonic())
        twin = ControllerTwin(core, "127.0.0.1", 0, reset_file=reset_file)
        await twin.start()
        client = AsyncModbusTcpClient("127.0.0.1", port=twin.port, timeout=1.0, retries=0, reconnect_delay=0)
        assert await client.connect()
        try:
            await client.write_register(reg.HR_COMMAND, reg.CMD_ENABLE, device_id=1)
            await client.write_register(reg.HR_COMMAND, reg.CMD_STOP, device_id=1)
            for cmd in (0, reg.CMD_RESET | reg.CMD_ENABLE, 0, reg.CMD_RESET, reg.CMD_ENABLE):
                await client.write_register(reg.HR_COMMAND, cmd, device_id=1)
            st = await read_state(client)
            assert st.fault == reg.FAULT_ESTOP and not st.has(reg.ST_ENABLED) and st.has(reg.ST_ESTOP)
            refused = core.network_resets_refused
            reset_file.touch()                           # the twin's own "CLI": the operator's reset key
            for _ in range(100):
                if core.local_resets:
                    break
                await asyncio.sleep(0.01)
            st = await read_state(client)
            assert st.fault == reg.FAULT_NONE and not st.has(reg.ST_ESTOP) and not st.has(reg.ST_ENABLED)
            await client.write_register(reg.HR_COMMAND, reg.CMD_ENABLE, device_id=1)
            st = await read_state(client)
            assert st.has(reg.ST_ENABLED)
            return refused
        finally:
            client.close()
            await twin.stop()

    refused = asyncio.run(scenario())
    print(f"\n[strict] e-stop: network RESET edges refused {refused}; cleared by the local reset")
    assert refused == 2


def test_a_watchdog_fault_needs_an_explicit_reset():
    core = _mb_enabled()
    core.write_holding(reg.HR_WATCHDOG, [1], 0.0)
    core.advance(5 * T_MB)
    assert core.fault == reg.FAULT_WATCHDOG and not core.enabled
    t = 5 * T_MB
    for k in range(10):                                  # counter and targets again: the fault stays
        t += T_MB
        core.write_holding(reg.HR_WATCHDOG, [k + 2, *reg.encode_joints(core.servo.q)], t)
        core.write_holding(reg.HR_COMMAND, [reg.CMD_ENABLE], t)
        core.advance(t)
    assert core.fault == reg.FAULT_WATCHDOG and not core.enabled
    core.write_holding(reg.HR_COMMAND, [reg.CMD_RESET | reg.CMD_ENABLE], t)   # the bridge's auto reset
    assert core.fault == reg.FAULT_NONE and core.enabled


# -------------------------------------------------------------------------------------- the bridge's counting
def _bad_targets(n: int) -> list[ArmTarget]:
    """``n`` bad targets for the left arm: the wrong arm, beyond reach, beyond a joint limit, not a
    rotation."""
    out = []
    for k in range(n):
        t = target("left", 0.0)
        pose, arm = t.pose.copy(), "left"
        kind = k % 4
        if kind == 0:
            arm = "right"
        elif kind == 1:
            pose[:3, 3] += [0.0, -1.0, 0.0]
        elif kind == 2:
            pose[:3, 3] += [0.0, 0.0, 0.3]
        else:
            pose[:3, :3] *= 2.0
        out.append(ArmTarget(header=Header(stamp=time.time()), arm=arm, pose=pose, source_stamp=1.0))
    return out


def test_the_tracker_refuses_every_bad_target_as_a_value_error():
    kin = ArmKinematics("left", LEFT_BASE, Q_LOWER + 0.02, Q_UPPER - 0.02)
    tr = TargetTracker(kin)
    tr.seed(home_joints("left"))
    n = 0
    for msg in _bad_targets(80):
        if msg.arm != "left":
            n += 1                      # the node refuses the wrong arm before IK
            continue
        with pytest.raises(ValueError) as exc:
            tr.set_target(msg.pose, msg.source_stamp, 0.0, strict=True)
        n += 1
        if isinstance(exc.value, TargetRefused):
            assert not exc.value.result.ok and tr.status(0.0).startswith("hold:")
    assert n == 80 and tr.refused == 40
    assert np.allclose(tr.goal, home_joints("left"))     # the goal never moved


def test_the_bridge_counts_80_of_80_bad_targets():
    async def scenario():
        twin = await start_twin("left")
        try:
            async with NodeHarness(ArmBridgeNode, params={"arm": "left", "port": twin.port}, name="b80") as h:
                await h.wait_for(topics.ARM_LEFT_STATE, n=3)
                h.inject(topics.ARM_LEFT_TARGET, target("left", 0.0))
                await asyncio.sleep(0.05)
                for msg in _bad_targets(80):             # a burst: no wait between them
                    h.inject(topics.ARM_LEFT_TARGET, msg)
                await asyncio.sleep(0.3)
                return h.rejected(topics.ARM_LEFT_TARGET), h.node.rejected_total
        finally:
            await twin.stop()

    per_topic, total = asyncio.run(scenario())
    print(f"\n[strict] bridge: bad targets counted {per_topic} (topic) / {total} (node) of 80")
    assert per_topic == 80 and total == 80


def test_the_bridge_tears_down_cleanly_after_a_configuration_error(tmp_path, caplog):
    bad = tmp_path / "display.yaml"
    bad.write_text("bogus: 1\n")

    async def scenario():
        async with NodeHarness(ArmBridgeNode, params={"arm": "left", "display_calib": str(bad)}, name="bad"):
            pass

    with caplog.at_level(logging.WARNING), pytest.raises(ConfigError, match="format_version"):
        asyncio.run(scenario())
    assert "teardown failed" not in caplog.text and "AttributeError" not in caplog.text


# ------------------------------------------------------------------------------------------- planner: time
def _ft(stamp, p=(0.02, 0.0, 0.0)):
    p = np.asarray(p, float)
    return Fingertip(header=Header(stamp=stamp), position=p, covariance=np.eye(3) * 1e-8, valid=True,
                     predicted_position=p, prediction_horizon=0.0, exposure_stamp=stamp - 0.012)


def test_planner_rejects_a_fingertip_from_the_future_alone_and_serves_the_next():
    async def scenario():
        params = {"object_stiffness": 20.0, "stiffness_from_scene": False}
        async with NodeHarness(PlannerNode, params=params) as h:
            for k in range(3):
                h.inject(topics.FINGERTIP, _ft(time.time(), (0.02, 0.001 * k, 0.0)))
                await h.wait_for(topics.SHEET_TARGET, n=k + 1)
            h.inject(topics.FINGERTIP, _ft(1e12))
            await h.wait_for(topics.SHEET_TARGET, n=4)
            for k in range(10):
                h.inject(topics.FINGERTIP, _ft(time.time(), (0.02, 0.003 + 0.001 * k, 0.0)))
                await h.wait_for(topics.SHEET_TARGET, n=5 + k)
            return ([m.status for m in h.messages(topics.SHEET_TARGET)], h.rejected(topics.FINGERTIP),
                    h.node.rejected_total, h.node.stage.planner.counts)

    statuses, rejected, total, counts = asyncio.run(scenario())
    served = [s for s in statuses[4:] if not s.startswith("hold")]
    print(f"\n[strict] planner: 1e12 stamp -> {statuses[3]}, rejected {rejected} (node {total}); "
          f"next good fingertips served {len(served)} of 10")
    assert statuses[3] == Hold.FUTURE_STAMP and rejected == 1 and total == 1
    assert len(served) == 10 and counts.get(Hold.STALE_FINGERTIP, 0) == 0


@pytest.mark.parametrize("back", [0.05, 5.0, 3600.0])
def test_planner_survives_a_backward_clock_step(back):
    pl = SurfacePlanner(make_shape("cylinder", {}), PlannerConfig())
    t = 1000.0
    dt = 1.0 / 48.0
    for k in range(10):
        t += dt
        assert not pl.update(t, (0.02, 0.001 * k, 0.0), now=t + 0.002).status.startswith("hold")
    t -= back                                            # the clock (stamps and now alike) steps back
    statuses = []
    for k in range(10):
        t += dt
        statuses.append(pl.update(t, (0.02, 0.01 + 0.001 * k, 0.0), now=t + 0.002).status)
    assert not any(s.startswith("hold") for s in statuses), statuses
    assert pl.counts.get("clock_rebase") == 1
    # an out-of-order sample while the clock is fine is still stale
    assert pl.update(t - 0.5, (0.02, 0.0, 0.0), now=t + 0.01).status == Hold.STALE_FINGERTIP
    # and without a clock a stamp far ahead is not judged (the pure planner's old contract)
    assert math.isfinite(pl.update(1e12, (0.02, 0.0, 0.0)).t)


# ----------------------------------------------------------------------------------------------- --check
@pytest.mark.parametrize("node, key, value", [("arm_left", "target_timeout", 1e9),
                                               ("arm_left", "accel_scale", 1e6),
                                               ("ctrl_left", "step_tolerance", 1e9),
                                               ("ctrl_left", "timeout_s", 1e9),
                                               ("planner", "future_stamp_tolerance", 1e9)])
def test_check_refuses_absurd_safety_params_naming_them(node, key, value):
    from conftest import ROOT

    res = check_launch(ROOT / "launch" / "sim.yaml", overrides={node: {key: value}})
    assert not res.ok
    line = [e for e in res.errors if key in e]
    assert line and f"node {node}" in line[0] and ("1000000000" in line[0] or "1e+09" in line[0]
                                                   or "1000000.0" in line[0]), res.errors
    print(f"\n[strict] --check: {line[0]}")


# ----------------------------------------------------------------------------------------------- helpers
class _UdpClient(asyncio.DatagramProtocol):
    """A UDP client on its own source port that keeps the decoded replies."""

    def __init__(self) -> None:
        self.replies: list[mxt.Packet] = []
        self.transport = None

    @classmethod
    async def open(cls, port: int) -> _UdpClient:
        loop = asyncio.get_running_loop()
        _, proto = await loop.create_datagram_endpoint(cls, remote_addr=("127.0.0.1", port))
        return proto

    def connection_made(self, transport) -> None:
        self.transport = transport

    def datagram_received(self, data: bytes, addr) -> None:
        self.replies.append(mxt.Packet.decode(data))

    def send(self, pkt: mxt.Packet) -> None:
        self.transport.sendto(pkt.encode())

    async def wait(self, n: int, timeout: float = 2.0) -> None:
        t_end = time.monotonic() + timeout
        while len(self.replies) < n and time.monotonic() < t_end:
            await asyncio.sleep(0.002)
        assert len(self.replies) >= n, f"{len(self.replies)} of {n} replies"

    def close(self) -> None:
        self.transport.close()
