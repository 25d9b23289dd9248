"""Bridge ↔ controller twin over real Modbus TCP sockets on 127.0.0.1 (free ports picked by the OS)."""

import asyncio
import math
import time

import numpy as np
from pymodbus.client import AsyncModbusTcpClient

from flexsheet.arm.kinematics import QD_MAX, home_joints
from flexsheet.model import geometry
from flexsheet.model.sheet import clamp_poses
from flexsheet.runtime.testing import NodeHarness
from flexsheet.twin.controller import ControllerCore
from flexsheet.twin.modbus_server import ControllerTwin
from messages import ArmJointState, ArmTarget, Header, topics
from messages import registers as reg
from nodes.arm_bridge.node import ArmBridgeNode

R_CYL = geometry.CYLINDER_RADIUS
SPEED_SCALE = 0.5     # bridge default


def clamp_pose(side, theta, stretch=0.05):
    c, s = math.cos(theta), math.sin(theta)
    L, R = clamp_poses(np.array([-R_CYL + R_CYL * c, 0.0, R_CYL * s]), np.array([c, 0.0, s]),
                             np.array([0.0, 1.0, 0.0]), stretch)
    return L if side == "left" else R


def target(side, theta, stamp=1.0):
    return ArmTarget(header=Header(stamp=time.time()), arm=side, pose=clamp_pose(side, theta),
                     source_stamp=stamp)


async def start_twin(side="left", port=0, q0=None):
    core = ControllerCore(home_joints(side) if q0 is None else q0, now=time.monotonic())
    twin = ControllerTwin(core, "127.0.0.1", port)
    await twin.start()
    return twin


async def read_state(client):
    rr = await client.read_input_registers(0, count=reg.IR_COUNT, device_id=1)
    assert not rr.isError()
    return reg.decode_input(rr.registers)


def test_watchdog_fault_and_recovery_over_modbus():
    async def scenario():
        twin = await start_twin()
        client = AsyncModbusTcpClient("127.0.0.1", port=twin.port, timeout=1.0, retries=0, reconnect_delay=0)
        assert await client.connect()
        try:
            assert not (await client.write_register(reg.HR_COMMAND, reg.CMD_ENABLE, device_id=1)).isError()
            for k in range(10):                      # counter running: stays enabled
                await client.write_register(reg.HR_WATCHDOG, k + 1, device_id=1)
                await asyncio.sleep(0.005)
            st = await read_state(client)
            assert st.has(reg.ST_ENABLED) and st.fault == reg.FAULT_NONE and st.has(reg.ST_WATCHDOG_OK)
            await asyncio.sleep(0.06)                    # stall > 3 periods (21.3 ms)
            st = await read_state(client)
            assert st.fault == reg.FAULT_WATCHDOG and st.has(reg.ST_FAULT) and st.has(reg.ST_HOLD)
            assert not st.has(reg.ST_ENABLED)
            # recovery: counter again, RESET edge + ENABLE
            await client.write_register(reg.HR_WATCHDOG, 100, device_id=1)
            assert not (await client.write_register(reg.HR_COMMAND, reg.CMD_RESET | reg.CMD_ENABLE,
                                                    device_id=1)).isError()
            st = await read_state(client)
            assert st.fault == reg.FAULT_NONE and st.has(reg.ST_ENABLED)
            assert np.max(np.abs(st.active - st.position)) < 1e-5    # resumes where it holds
        finally:
            client.close()
            await twin.stop()
    asyncio.run(scenario())


def test_malformed_registers_get_modbus_error_and_no_motion():
    async def scenario():
        twin = await start_twin()
        client = AsyncModbusTcpClient("127.0.0.1", port=twin.port, timeout=1.0, retries=0, reconnect_delay=0)
        assert await client.connect()
        try:
            await client.write_register(reg.HR_COMMAND, reg.CMD_ENABLE, device_id=1)
            q0 = (await read_state(client)).position
            bad = [
                (reg.HR_COMMAND, [0x0008], reg.REJ_COMMAND_BITS, 3),
                (reg.HR_TARGET + 3, [1, 2], reg.REJ_PARTIAL_PAIR, 3),
                (reg.HR_TARGET, reg.encode_joints(q0 + [0, 0, 2.0, 0, 0, 0]), reg.REJ_TARGET_LIMIT, 3),
                (reg.HR_TARGET, reg.encode_joints(q0 + [0, 0.3, 0, 0, 0, 0]), reg.REJ_TARGET_STEP, 3),
            ]
            for k, (address, values, code, exc_code) in enumerate(bad):
                await client.write_register(reg.HR_WATCHDOG, k + 1, device_id=1)
                rr = await client.write_registers(address, values, device_id=1)
                assert rr.isError() and rr.exception_code == exc_code
                st = await read_state(client)
                assert st.reject == code and st.has(reg.ST_REJECTED)
            rr = await client.write_registers(reg.HR_COUNT, [0], device_id=1)     # outside the map
            assert rr.isError() and rr.exception_code == 2
            await client.write_register(reg.HR_WATCHDOG, 99, device_id=1)
            await asyncio.sleep(0.015)
            st = await read_state(client)
            assert np.max(np.abs(st.position - q0)) < 2e-6 and np.max(np.abs(st.velocity)) < 1e-5
            assert twin.core.rejections == len(bad)
        finally:
            client.close()
            await twin.stop()
    asyncio.run(scenario())


def _max_step(commanded):
    c = np.array(commanded)
    return np.max(np.abs(np.diff(c, axis=0)) / (SPEED_SCALE * QD_MAX * 0.0071))


def test_bridge_tracks_and_reconnects_after_twin_restart_without_jump():
    async def scenario():
        twin = await start_twin("left")
        port = twin.port
        params = {"arm": "left", "port": port, "backoff_min": 0.02, "backoff_max": 0.1, "target_timeout": 1.0}
        async with NodeHarness(ArmBridgeNode, params=params, name="bridge_left") as h:
            for k in range(25):                           # slow tilt, 0 → 0.2 rad
                h.inject(topics.ARM_LEFT_TARGET, target("left", 0.008 * k, stamp=float(k)))
                await asyncio.sleep(0.02)
            q_stop = twin.core.servo.q.copy()
            await twin.stop()                             # controller goes away mid-motion
            await asyncio.sleep(0.15)
            assert h.node.stream.connected is False
            twin2 = await start_twin("left", port=port, q0=twin.core.servo.q)   # arm did not move meanwhile
            twin2.core.target_log = []
            try:
                for k in range(25, 60):
                    h.inject(topics.ARM_LEFT_TARGET, target("left", min(0.2, 0.008 * k), stamp=float(k)))
                    await asyncio.sleep(0.02)
                await asyncio.sleep(0.5)
                states = h.messages(topics.ARM_LEFT_STATE)
                assert h.node.stream.reconnects >= 2
                assert twin2.core.rejections == 0
                log = np.array(twin2.core.target_log)
                assert len(log) > 20
                assert np.max(np.abs(log[0] - q_stop)) <= SPEED_SCALE * np.max(QD_MAX) * 0.0071 * 2
                assert _max_step(log) <= 1.0 + 1e-6
                assert _max_step([m.commanded for m in states]) <= 1.0 + 1e-6
                last = states[-1]
                assert last.bridge_status == "ok" and last.target_stamp == 59.0
                want = clamp_pose("left", 0.2)
                assert np.linalg.norm(last.pose[:3, 3] - want[:3, 3]) < 1e-4
                assert last.write_stamp > 0 and abs(last.write_stamp - last.header.stamp) < 0.05
            finally:
                await twin2.stop()
    asyncio.run(scenario())


def test_two_bridges_run_concurrently():
    async def scenario():
        twins = {side: await start_twin(side) for side in ("left", "right")}
        assert twins["left"].port != twins["right"].port
        try:
            async with NodeHarness(ArmBridgeNode, params={"arm": "left", "port": twins["left"].port},
                                   name="bl") as hl, \
                    NodeHarness(ArmBridgeNode, params={"arm": "right", "port": twins["right"].port},
                                name="br") as hr:
                want = {side: clamp_pose(side, -0.39) for side in ("left", "right")}

                def settled(side, h):
                    st = h.messages(topics.arm_state(side))[-1]
                    return np.linalg.norm(st.pose[:3, 3] - want[side][:3, 3]) < 1e-4 and np.allclose(
                        st.pose[:3, :3], want[side][:3, :3], atol=1e-4)

                for k in range(200):                      # ramp to -0.39 rad, then keep sending it
                    th = -0.01 * min(k, 39)
                    hl.inject(topics.ARM_LEFT_TARGET, target("left", th))
                    hr.inject(topics.ARM_RIGHT_TARGET, target("right", th))
                    await asyncio.sleep(0.02)
                    # settled (a watchdog trip from a scheduling stall on a loaded machine pauses an arm)
                    if k >= 60 and settled("left", hl) and settled("right", hr):
                        break
                for side, h in (("left", hl), ("right", hr)):
                    st = h.messages(topics.arm_state(side))[-1]
                    assert st.arm == side and st.bridge_status == "ok" and st.fault == 0
                    assert np.linalg.norm(st.pose[:3, 3] - want[side][:3, 3]) < 1e-4
                    assert np.allclose(st.pose[:3, :3], want[side][:3, :3], atol=1e-4)
                    assert twins[side].core.rejections == 0
        finally:
            for t in twins.values():
                await t.stop()
    asyncio.run(scenario())


def test_bridge_holds_on_lost_or_unreachable_targets_and_follows_estop():
    async def scenario():
        twin = await start_twin("left")
        params = {"arm": "left", "port": twin.port, "target_timeout": 0.1}
        try:
            async with NodeHarness(ArmBridgeNode, params=params, name="bh") as h:
                for k in range(100):
                    h.inject(topics.ARM_LEFT_TARGET, target("left", 0.01 * min(k, 9)))
                    await asyncio.sleep(0.02)
                    last = [m.commanded for m in h.messages(topics.ARM_LEFT_STATE)[-5:]]
                    # the command reached the last good goal (a stall on a loaded machine can delay it)
                    if k >= 9 and len(last) == 5 and np.ptp(np.array(last), axis=0).max() < 1e-12:
                        break
                await asyncio.sleep(0.3)                  # planner silent beyond the timeout
                st = h.messages(topics.ARM_LEFT_STATE)[-1]
                assert st.bridge_status == "hold:no_target"
                q_hold = st.commanded
                far = target("left", 0.0)
                pose = far.pose.copy()
                pose[:3, 3] += [0.0, -1.0, 0.0]          # 1 m beyond the arm's reach
                n_before = len(h.messages(topics.ARM_LEFT_STATE))
                for _ in range(5):
                    h.inject(topics.ARM_LEFT_TARGET, ArmTarget(header=Header(stamp=time.time()), arm="left",
                                                              pose=pose, source_stamp=5.0))
                    await asyncio.sleep(0.02)
                after = h.messages(topics.ARM_LEFT_STATE)[n_before:]
                statuses = {m.bridge_status for m in after}
                assert "hold:unreachable" in statuses or any(s.startswith("hold:limit") for s in statuses)
                # the command stays put (1e-5 rad allows a re-seed at the measured joints after a
                # watchdog trip caused by a scheduling stall on a loaded machine)
                assert max(np.max(np.abs(m.commanded - q_hold)) for m in after) < 1e-5
                # e-stop from another client: the bridge reports it and does not fight it
                client = AsyncModbusTcpClient("127.0.0.1", port=twin.port, timeout=1.0, retries=0,
                                              reconnect_delay=0)
                assert await client.connect()
                await client.write_register(reg.HR_COMMAND, reg.CMD_STOP, device_id=1)
                await asyncio.sleep(0.1)
                st = h.messages(topics.ARM_LEFT_STATE)[-1]
                assert st.bridge_status == "fault:estop" and st.fault == reg.FAULT_ESTOP
                rr = await client.write_register(reg.HR_COMMAND, reg.CMD_RESET | reg.CMD_ENABLE, device_id=1)
                assert not rr.isError()  # accepted, but a network RESET never clears an e-stop
                await asyncio.sleep(0.1)
                st = h.messages(topics.ARM_LEFT_STATE)[-1]
                assert st.bridge_status == "fault:estop" and st.fault == reg.FAULT_ESTOP
                assert twin.local_reset()                 # the operator's reset at the controller
                await asyncio.sleep(0.1)
                h.inject(topics.ARM_LEFT_TARGET, target("left", 0.05))
                await asyncio.sleep(0.1)
                st = h.messages(topics.ARM_LEFT_STATE)[-1]
                assert st.bridge_status == "ok" and st.fault == 0
                client.close()
                assert h.rejected(topics.ARM_LEFT_TARGET) == 5   # the 5 unreachable targets, each counted
        finally:
            await twin.stop()
    asyncio.run(scenario())


class _CancelSwallowingLink:
    """A controller link whose first read after a cancellation returns the state instead of raising
    ``CancelledError``: what Python 3.11's ``asyncio.wait_for`` inside pymodbus does when the reply and the
    cancellation arrive together (CPython gh-86296)."""

    name = "fake"
    rewrite_ok = False

    def __init__(self):
        self.connected, self.on_ready, self.swallowed, self.closed = False, None, 0, False
        self.state = reg.ControllerState(reg.ST_ENABLED, 0, 0, 0, home_joints("left"), np.zeros(6), 0,
                                         home_joints("left"))

    async def open(self):
        self.connected = True
        return True

    async def read(self):
        try:
            await asyncio.sleep(0.02)             # longer than the period: the loop is nearly always here
        except asyncio.CancelledError:
            if self.swallowed == 0:          # the race: the reply wins, the cancellation is lost
                self.swallowed += 1
                return self.state
            raise
        return self.state

    def supervise(self, st):
        from flexsheet.arm.stream import Verdict
        return Verdict(False, "hold:disabled", st.position)

    async def send(self, cmd, rewrite=False):
        return True

    async def keepalive(self):
        pass

    async def after_cycle(self):
        pass

    def ready_time(self):
        return None

    def next_deadline(self, deadline, t_start, period):
        return deadline + period

    async def close(self, end=False):
        self.closed = True

    def counters(self):
        return {}


def test_stream_stop_ends_the_loop_when_a_cancellation_is_swallowed():
    """A lost cancellation (a reply and the cancel arriving together in pymodbus's ``wait_for``) must not keep
    the stream running: ``stop`` returns (bounded here by 2 s; it used to wait forever, and the node harness
    timed out after 5 s) and closes the link."""
    from flexsheet.arm.kinematics import Q_LOWER, Q_UPPER, ArmKinematics
    from flexsheet.arm.limiter import StreamLimiter
    from flexsheet.arm.stream import ArmStream
    from flexsheet.arm.tracking import TargetTracker
    from flexsheet.model.geometry import LEFT_BASE

    async def scenario():
        link = _CancelSwallowingLink()
        kin = ArmKinematics("left", LEFT_BASE, Q_LOWER + 0.02, Q_UPPER - 0.02)
        lim = StreamLimiter(home_joints("left"), 0.0071, 0.5 * QD_MAX, QD_MAX, Q_LOWER, Q_UPPER, 0.02)
        stream = ArmStream(TargetTracker(kin, target_timeout=1.0), lim, link)
        task = stream.start()
        while stream.cycles < 5:
            await asyncio.sleep(0.005)
        # cancel while the loop is inside read(): the first cancellation is swallowed there
        while link.swallowed == 0:
            stopping = asyncio.ensure_future(stream.stop(end=True))
            await asyncio.wait({stopping}, timeout=2.0)      # (asyncio.wait cancels nothing on timeout)
            if not stopping.done():
                task.cancel()                                 # clean up the runaway loop, then fail
                await asyncio.wait({stopping}, timeout=2.0)
                raise AssertionError("ArmStream.stop did not return within 2 s (the loop ran on)")
            assert task.done() and link.closed
            if link.swallowed == 0:          # the cancel landed in the inter-cycle wait: run again
                link.closed = False
                task = stream.start()
                await asyncio.sleep(0.003)
        return link.swallowed

    assert asyncio.run(scenario()) == 1


def test_arm_services_hold_move_to_home_and_release_within_the_limits():
    """The bridge's services (flexsheet service call arm_left hold|move_to|home|release): hold stays where the
    arm is and ignores targets (counted, not rejections); move_to streams to the joints within the speed
    limit; a joint outside its limit or an unreachable pose is refused naming it and nothing moves; home
    reaches the home sheet's clamp pose; release follows targets again."""
    async def scenario():
        twin = await start_twin("left")
        params = {"arm": "left", "port": twin.port, "backoff_min": 0.02, "backoff_max": 0.1,
                  "target_timeout": 1.0}
        try:
            async with NodeHarness(ArmBridgeNode, params=params, name="arm_left") as h:
                svc = h.node._pending_services
                call = {name: handler for name, (handler, *_) in svc.items()}
                await asyncio.sleep(0.1)
                q0 = np.array(call["hold"]({}))
                h.inject(topics.ARM_LEFT_TARGET, target("left", 0.2, stamp=1.0))
                await asyncio.sleep(0.2)
                assert np.max(np.abs(twin.core.servo.q - q0)) < 1e-6            # held: the target was ignored
                # by design: not a rejection
                assert h.node.ignored_while_held >= 1 and h.node.rejected_total == 0
                goal = q0 + np.array([0.1, -0.05, 0.05, 0.0, 0.0, 0.1])
                t0 = time.monotonic()
                call["move_to"]({"joints": goal.tolist()})
                twin.core.target_log = []
                while np.max(np.abs(twin.core.servo.q - goal)) > 1e-3 and time.monotonic() - t0 < 5.0:
                    await asyncio.sleep(0.02)
                assert np.max(np.abs(twin.core.servo.q - goal)) <= 1e-3
                assert _max_step(twin.core.target_log) <= 1.0 + 1e-6                # within the speed limit
                for bad, why in (({"joints": [0.0, 0.0, 3.0, 0.0, 0.0, 0.0]}, "J3"),
                                 ({"pose": np.eye(4).tolist()}, "unreachable"),
                                 ({}, "one of joints")):
                    try:
                        call["move_to"](bad)
                        raise AssertionError(f"{bad} accepted")
                    except ValueError as exc:
                        assert why in str(exc), exc
                assert np.max(np.abs(h.node.tracker.manual - goal)) < 1e-12  # the refusals moved nothing
                q_home = np.array(call["home"]({}))
                while np.max(np.abs(twin.core.servo.q - q_home)) > 1e-3 and time.monotonic() - t0 < 10.0:
                    await asyncio.sleep(0.02)
                want = clamp_pose("left", 0.0)
                assert np.linalg.norm(h.node.fk_kin.fk(twin.core.servo.q)[:3, 3] - want[:3, 3]) < 1e-3
                call["release"]({})
                for k in range(10):
                    h.inject(topics.ARM_LEFT_TARGET, target("left", 0.002 * k, stamp=10.0 + k))
                    await asyncio.sleep(0.02)
                await asyncio.sleep(0.3)
                assert h.node.tracker.status(h.node.now()) == "ok"
        finally:
            await twin.stop()
    asyncio.run(scenario())


def _peer_state(side: str, status: str, theta: float = 0.0) -> ArmJointState:
    """The partner's joint state with ``status``, its clamp where a sheet tangent at ``theta`` puts it (the
    span guard measures the span to it)."""
    z = np.zeros(6)
    return ArmJointState(header=Header(stamp=time.time()), arm=side, position=home_joints(side), velocity=z,
                         commanded=z, executing=z, pose=clamp_pose(side, theta), status=0,
                         bridge_status=status)


def test_the_arm_holds_while_the_other_cannot_follow_and_follows_again_after_it():
    """The sheet couples the clamps: while the right arm holds on a joint limit (its joint state says
    hold:limit:J3), the left arm stops where it is (hold:peer) within a few cycles and does not move on new
    targets; a partner that only lacks targets holds nobody; once the right arm follows, the left one reaches
    its target."""
    async def scenario():
        twin = await start_twin("left")
        params = {"arm": "left", "port": twin.port, "target_timeout": 1.0}
        try:
            async with NodeHarness(ArmBridgeNode, params=params, name="arm_left") as h:
                for k in range(30):                                  # following a ramp
                    h.inject(topics.ARM_LEFT_TARGET, target("left", -0.005 * k, stamp=1.0 + k))
                    await asyncio.sleep(0.01)
                h.inject(topics.ARM_RIGHT_STATE, _peer_state("right", "hold:limit:J3"))
                await asyncio.sleep(0.05)
                assert h.messages(topics.ARM_LEFT_STATE)[-1].bridge_status == "hold:peer"
                for _ in range(200):                                 # braking from the ramp's speed (0.1 s
                    await asyncio.sleep(0.01)                        # quiet; longer on a loaded machine)
                    if np.max(np.abs(twin.core.servo.v)) < 1e-6:
                        break
                q_held = twin.core.servo.q.copy()
                for k in range(20):                                  # targets go on far away: not followed
                    h.inject(topics.ARM_LEFT_TARGET, target("left", -0.3, stamp=40.0 + k))
                    await asyncio.sleep(0.01)
                assert np.max(np.abs(twin.core.servo.q - q_held)) < 1e-3, np.abs(twin.core.servo.q - q_held)
                assert h.messages(topics.ARM_LEFT_STATE)[-1].bridge_status == "hold:peer"
                h.inject(topics.ARM_RIGHT_STATE, _peer_state("right", "hold:no_target", -0.3))  # not a reason
                for k in range(150):
                    h.inject(topics.ARM_LEFT_TARGET, target("left", -0.3, stamp=60.0 + k))
                    await asyncio.sleep(0.01)
                last = h.messages(topics.ARM_LEFT_STATE)[-1]
                assert last.bridge_status == "ok", last.bridge_status
                assert np.linalg.norm(last.pose[:3, 3] - clamp_pose("left", -0.3)[:3, 3]) < 2e-3
        finally:
            await twin.stop()
    asyncio.run(scenario())


def test_the_in_process_controller_twin_is_refused_on_the_wall_clock_naming_the_fix():
    """``source: sim`` is the controller twin reached at simulated instants: on the wall clock the bridge does
    not start, and says to use ``clock: sim`` or reach a controller twin node over the network
    (``source: tcp``)."""
    import pytest

    async def scenario():
        async with NodeHarness(ArmBridgeNode, params={"arm": "left", "source": "sim"}):
            pass
    with pytest.raises(Exception, match=r"source sim is the controller twin.*clock: sim.*source: tcp"):
        asyncio.run(scenario())


def test_the_arm_bridge_and_camera_params_refuse_an_uninstalled_source_with_its_field():
    import pytest
    from pydantic import ValidationError

    from nodes.arm_bridge.params import ArmBridgeParams
    from nodes.camera.node import CameraParams

    with pytest.raises(ValidationError, match=r"source\n.*unknown controller source 'rs232'"):
        ArmBridgeParams(source="rs232")
    with pytest.raises(ValidationError, match=r"source\n.*unknown camera source 'webcam'; installed: device, "
                                              r"files, genicam, sim"):
        CameraParams(source="webcam")
    assert CameraParams(source="files").source == "files"


def test_the_planners_joints_are_taken_when_right_and_a_malformed_joints_field_is_refused_by_name():
    """A target carrying the planner's IK (``ArmTarget.joints``) is taken without solving again (counted);
    joints of the wrong length are refused naming the field, and the arm keeps its goal."""
    from flexsheet.arm.kinematics import ArmKinematics
    from flexsheet.model.geometry import LEFT_BASE

    async def scenario():
        twin = await start_twin("left")
        try:
            async with NodeHarness(ArmBridgeNode, params={"arm": "left", "port": twin.port}, name="bj") as h:
                while h.node.tracker.goal is None:
                    await asyncio.sleep(0.01)
                good = target("left", 0.02)
                q = ArmKinematics("left", LEFT_BASE).ik(good.pose, h.node.tracker.goal).q
                h.inject(topics.ARM_LEFT_TARGET, good.model_copy(update={"joints": q}))
                await h.settle(0.1)
                assert h.node.tracker.planned_taken == 1 and h.node.tracker.planned_solved == 0
                assert np.abs(h.node.tracker.goal - q).max() < 1e-7
                bad = target("left", 0.04, stamp=2.0).model_copy(update={"joints": np.zeros(3)})
                h.inject(topics.ARM_LEFT_TARGET, bad)
                await h.settle(0.1)
                assert h.rejected(topics.ARM_LEFT_TARGET) == 1
                assert "joints (the publisher's IK)" in h.node.last_rejection
                assert np.abs(h.node.tracker.goal - q).max() < 1e-7 and h.node.tracker.source_stamp == 1.0
        finally:
            await twin.stop()
    asyncio.run(scenario())
