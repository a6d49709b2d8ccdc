"""Launch on real-autopilot timing (issue 8, item 6): the ready wait, the take-off heading, the
HEARTBEAT interval refusal note."""

from __future__ import annotations

import asyncio
import io
import math
import types

import numpy as np
import pytest
from pymavlink.dialects.v20 import common as mavlink2
from sitl_mock.config import MockConfig, SpawnSpec
from sitl_mock.runner import run_in_thread

from pf_offboard.app.flight import Flight as Bridge
from pf_offboard.app.flight import FlightOptions as BridgeOptions
from pf_offboard.app.rules import EndSpec
from pf_offboard.app.encoders import Encoder
from pf_offboard.app.estimator import Estimator
from pf_offboard.app.fly import fly
from pf_offboard.app.pipeline import Pipeline
from pf_offboard.app.profiles import PX4
from pf_offboard.logs.tlog import read_tlog

from .flights import RATE_HZ, fly_args, write_config
from .helpers import attitude_quaternion, local_position, quat_about


class _FakeLink:
    """Just enough of Link for the bridge's launch logic: records what is sent."""

    def __init__(self) -> None:
        self.target = types.SimpleNamespace(system=1, component=1)
        self.first_heartbeat = None
        self.sent: list = []

    def send(self, msg) -> None:  # noqa: ANN001
        self.sent.append(msg)

    def send_heartbeat(self) -> None:
        pass


class _Follower:
    speed = -1.5

    def reset(self) -> None:
        pass


def _bridge(ready_timeout_s: float = 5.0) -> Bridge:
    pipe = Pipeline(_Follower(), Encoder("acceleration", PX4, 1, 1), Estimator("local_position"))
    opts = BridgeOptions(launch="takeoff", height_m=2.0, end=EndSpec(laps=1), status=False, ready_timeout_s=ready_timeout_s)
    return Bridge(_FakeLink(), PX4, pipe, opts, 15.0, True, 1.0, status_stream=io.StringIO())  # type: ignore[arg-type]


def test_takeoff_heading_waits_for_an_attitude_sample() -> None:
    """Position before attitude: the first state sample has no attitude (its yaw would default to
    east). The take-off's state must be one that carries the vehicle's real heading (north here)."""
    bridge = _bridge()
    north = quat_about((0.0, 0.0, 1.0), 0.0)  # NED yaw 0 = facing north = ENU yaw +90°

    async def scenario() -> float:
        task = asyncio.ensure_future(bridge._first_state(bridge.clock() + 5.0, need_attitude=True))
        bridge.on_message(local_position(10))  # position first: no attitude yet
        # wake the waiter as any event would and let it look (it clears the event to wait again):
        # a condition, not a wall-clock pause
        bridge.waiter.changed.set()
        deadline = asyncio.get_running_loop().time() + 5.0
        while bridge.waiter.changed.is_set() and not task.done() and asyncio.get_running_loop().time() < deadline:
            await asyncio.sleep(0)
        assert not bridge.waiter.changed.is_set()  # it looked at the position-only state ...
        assert not task.done()  # ... and still waits for the attitude
        bridge.on_message(attitude_quaternion(12, q_ned_frd=tuple(north)))
        bridge.on_message(local_position(20))
        est = await asyncio.wait_for(task, 2.0)
        from pf_offboard.app.encoders import yaw_of

        return yaw_of(est.q_enu_flu)

    yaw = asyncio.run(scenario())
    assert yaw == pytest.approx(math.pi / 2)


def test_first_state_gives_up_after_the_ready_timeout_naming_the_flag() -> None:
    bridge = _bridge()
    from pf_offboard.errors import LinkError

    async def scenario() -> None:
        await bridge._first_state(bridge.clock() + 0.3, need_attitude=False)

    with pytest.raises(LinkError, match="--ready-timeout"):
        asyncio.run(scenario())


@pytest.mark.integration
def test_ardupilot_takeoff_waits_for_the_position_estimate(tmp_path) -> None:
    """ArduCopter SITL is armable only ~42 s after boot and sends LOCAL_POSITION_NED only once its
    EKF has an origin. The mock at 4x real time with a 60 s EKF delay (its clock runs from its own
    start, so the app waits ~10 s of wall clock, beyond the old 3-5 s limit): --takeoff waits
    (progress lines), arms, takes off and follows; exit 0."""
    cfg = MockConfig(vehicle="fast", profile="ardupilot", spawn=SpawnSpec.parse("ground"), udp_local_port=0, udp_remote=None,
                     speed=4.0, ekf_ready_delay_s=30.0)  # fmt: skip
    config = write_config(tmp_path, setpoint_rate_hz=50.0)
    status = io.StringIO()
    with run_in_thread(cfg) as mock:
        args = fly_args("--connect", f"udpout:127.0.0.1:{mock.ports.udp}", "--config", str(config), "--log-dir",
                        str(tmp_path / "log"), "--heartbeat-timeout", "5", "--takeoff", "2", "--duration", "1",
                        "--output", "attitude", "--set-guid-options")  # fmt: skip
        outcome = fly(args, status_stream=status)
    text = status.getvalue()
    assert outcome.exit_code == 0, text[-2000:]
    assert "waiting for the vehicle's position estimate" in text
    entries = read_tlog(tmp_path / "log" / "flight.tlog")
    first_state = next(e for e in entries if e.direction == "in" and e.message.get_type() == "LOCAL_POSITION_NED")
    assert first_state.message.time_boot_ms >= 30_000  # the estimate really was late
    assert first_state.time_unix_s - entries[0].time_unix_s > 5.0  # longer than the old limit
    takeoff = [e for e in entries if e.direction == "out" and e.message.get_type() == "COMMAND_LONG" and e.message.command == mavlink2.MAV_CMD_NAV_TAKEOFF]
    assert takeoff


@pytest.mark.integration
def test_heartbeat_interval_refusal_is_one_note_line(tmp_path) -> None:
    """PX4 refuses SET_MESSAGE_INTERVAL for HEARTBEAT (COMMAND_ACK FAILED): one note line, even
    with --quiet, not an error; the flight goes on."""
    cfg = MockConfig(vehicle="fast", profile="px4", spawn=SpawnSpec.parse("hover:-3,0,-2"), udp_local_port=0, udp_remote=None,
                     lockstep=True, lockstep_dt_s=1.0 / RATE_HZ)  # fmt: skip
    # one lockstep step per setpoint period, as in the other lockstep flights: at 4 ms a step most
    # setpoints brought no fresh state (streamed at 100 Hz), so the flight advanced on the app's
    # 10 Hz keep-alive (~19 s of wall time for this 1 s flight)
    config = write_config(tmp_path)
    status = io.StringIO()
    with run_in_thread(cfg) as mock:

        def refuse_heartbeat(m) -> None:  # noqa: ANN001
            original = m.autopilot._cmd_message_interval

            def patched(msgid: int, interval_us: float, link: int) -> int:
                return mavlink2.MAV_RESULT_FAILED if msgid == mavlink2.MAVLINK_MSG_ID_HEARTBEAT else original(msgid, interval_us, link)

            m.autopilot._cmd_message_interval = patched

        mock.call(refuse_heartbeat)
        args = fly_args("--connect", f"udpout:127.0.0.1:{mock.ports.udp}", "--config", str(config), "--log-dir",
                        str(tmp_path / "log"), "--heartbeat-timeout", "5", "--quiet", "--airborne", "--duration", "1")  # fmt: skip
        outcome = fly(args, status_stream=status)
    assert outcome.exit_code == 0, outcome.reason
    lines = [line for line in status.getvalue().splitlines() if "refused" in line]
    assert len(lines) == 1, status.getvalue()
    assert lines[0].startswith("note: ") and "HEARTBEAT" in lines[0] and "COMMAND_ACK FAILED" in lines[0]
    assert not [line for line in status.getvalue().splitlines() if line.startswith(("error", "pf-offboard fly: link error", "warning"))]
    # the state streams were still requested and honoured: the flight was driven by them
    assert np.isfinite(outcome.summary.whole_cross_track_rms_m)


@pytest.mark.integration
def test_px4_takeoff_retries_arming_until_the_checks_pass(tmp_path) -> None:
    """PX4 refuses arming (TEMPORARILY_REJECTED, "no position estimate") until its estimator is
    ready: --takeoff keeps retrying with progress lines instead of giving up after 5 s, then
    arms, climbs and follows. The mock at 4x real time, estimate ready at 30 s of vehicle time (7.5 s of wall time)."""
    cfg = MockConfig(vehicle="fast", profile="px4", spawn=SpawnSpec.parse("ground"), udp_local_port=0, udp_remote=None,
                     speed=4.0, ekf_ready_delay_s=30.0)  # fmt: skip
    config = write_config(tmp_path, setpoint_rate_hz=50.0)
    status = io.StringIO()
    with run_in_thread(cfg) as mock:
        args = fly_args("--connect", f"udpout:127.0.0.1:{mock.ports.udp}", "--config", str(config), "--log-dir",
                        str(tmp_path / "log"), "--heartbeat-timeout", "5", "--takeoff", "2", "--duration", "1")  # fmt: skip
        outcome = fly(args, status_stream=status)
    text = status.getvalue()
    assert outcome.exit_code == 0, text[-2000:]
    assert "waiting for arming" in text
    entries = read_tlog(tmp_path / "log" / "flight.tlog")
    arm_acks = [e for e in entries if e.direction == "in" and e.message.get_type() == "COMMAND_ACK"
                and e.message.command == mavlink2.MAV_CMD_COMPONENT_ARM_DISARM]  # fmt: skip
    refused = [e for e in arm_acks if e.message.result == mavlink2.MAV_RESULT_TEMPORARILY_REJECTED]
    accepted = [e for e in arm_acks if e.message.result == mavlink2.MAV_RESULT_ACCEPTED]
    assert refused and accepted and refused[0].time_unix_s < accepted[0].time_unix_s
    assert accepted[0].time_unix_s - refused[0].time_unix_s > 5.0  # beyond the old 5 s limit


def test_only_an_accepted_attitude_counts_as_fresh() -> None:
    """Rates mode flies only on a fresh attitude. An ATTITUDE_QUATERNION the estimator refuses
    (older than the last one, or future-dated) arrives but is not a fresh attitude: it must not
    renew the freshness the level-hold fallback is judged by."""
    now = [100.0]
    pipe = Pipeline(_Follower(), Encoder("rates", PX4, 1, 1), Estimator("local_position"))
    opts = BridgeOptions(launch="airborne", height_m=math.nan, end=EndSpec(laps=1), status=False)
    bridge = Bridge(_FakeLink(), PX4, pipe, opts, 15.0, True, 1.0, status_stream=io.StringIO(), clock=lambda: now[0])  # type: ignore[arg-type]
    bridge.on_message(attitude_quaternion(2000))
    assert bridge._last_attitude_wall == 100.0
    now[0] = 101.0
    bridge.on_message(attitude_quaternion(1990))  # reordered: older than the last
    bridge.on_message(attitude_quaternion(9000))  # future-dated: a candidate, refused
    assert pipe.estimator.rejected == 2 and bridge._last_attitude_wall == 100.0
    bridge.on_message(attitude_quaternion(2004))  # the genuine stream continues
    assert bridge._last_attitude_wall == 101.0
