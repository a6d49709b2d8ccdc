"""Lockstep over loopback UDP: each setpoint advances one step; same seed + inputs ⇒ same telemetry."""

from __future__ import annotations

import socket

import pytest
from pymavlink.dialects.v20 import common as mavlink

from sitl_mock.config import FaultConfig, MockConfig, SpawnSpec
from sitl_mock.runner import run_in_thread, spawn
from sitl_mock.testing import UdpClient, accel_setpoint, command_long

pytestmark = pytest.mark.integration

STEPS = 400
# Keepalive HEARTBEAT / SYS_STATUS depend on wall time by design; everything else must repeat.
_WALL_PACED = {"HEARTBEAT", "SYS_STATUS"}


def _collect(client: UdpClient, records: list[str], until_lpn: bool) -> None:
    """Receive until this step's LOCAL_POSITION_NED (or a short timeout when it was lost)."""
    try:
        while True:
            msgs = client.recv()
            for msg in msgs:
                if msg.get_type() not in _WALL_PACED:
                    records.append(repr(sorted(msg.to_dict().items())))  # repr: NaN == NaN
            if until_lpn and any(m.get_type() == "LOCAL_POSITION_NED" for m in msgs):
                return
    except (TimeoutError, socket.timeout):
        pass


def _fly(seed: int, faults: FaultConfig) -> tuple[list[str], float, float]:
    config = MockConfig(vehicle="fast", udp_local_port=0, udp_remote=None, lockstep=True, seed=seed, faults=faults,
                        spawn=SpawnSpec("hover", (0.0, 0.0, -10.0)))
    records: list[str] = []
    with run_in_thread(config) as mock, UdpClient(mock.ports.udp, timeout_s=0.02) as client:
        client.send(mavlink.MAVLink_heartbeat_message(6, 8, 0, 0, 0, 3))
        client.send(command_long(mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, mavlink.MAVLINK_MSG_ID_LOCAL_POSITION_NED, 4000))
        for i in range(STEPS):
            if i == 50:
                client.send(command_long(mavlink.MAV_CMD_DO_SET_MODE, 1, 6))
            client.send(accel_setpoint(1.0 if i < 300 else -1.0, 0.5, -0.2, yaw=0.0))
            _collect(client, records, until_lpn=True)  # paced by the step's LOCAL_POSITION_NED
        _collect(client, records, until_lpn=False)
        sim_time, x = mock.time_s, float(mock.truth.position_ned_m[0])
    return records, sim_time, x


def test_lockstep_advances_one_step_per_setpoint_and_flies() -> None:
    records, sim_time, x = _fly(1, FaultConfig())
    assert sim_time == pytest.approx(STEPS * 0.004, abs=1e-9)
    assert x > 0.5  # OFFBOARD from step 50, accelerating north
    lpn = [r for r in records if "'LOCAL_POSITION_NED'" in r]
    assert len(lpn) >= STEPS - 5  # one per step at 250 Hz


def test_lockstep_is_deterministic_with_faults() -> None:
    faults = FaultConfig(loss=0.05, duplicate=0.05, corrupt=0.02)
    a = _fly(7, faults)
    b = _fly(7, faults)
    c = _fly(8, faults)
    assert a == b
    assert a[0] != c[0]  # a different seed draws different faults


def test_spawned_subprocess_serves_and_stops() -> None:
    config = MockConfig(vehicle="fast", udp_local_port=0, udp_remote=None, lockstep=True)
    with spawn(config) as handle, UdpClient(handle.ports.udp) as client:
        client.send(mavlink.MAVLink_heartbeat_message(6, 8, 0, 0, 0, 3))
        hb = client.wait("HEARTBEAT", timeout_s=5.0)
        assert hb.autopilot == mavlink.MAV_AUTOPILOT_PX4
        for _ in range(3):
            client.send(accel_setpoint(0, 0, 0))
        att = client.wait("ATTITUDE", timeout_s=5.0)
        assert att.time_boot_ms == 12  # 100 Hz: due after the third 4 ms lockstep step
    assert handle.process.returncode is not None


def test_set_speed_changes_the_own_clocks_pace_and_is_refused_in_lockstep() -> None:
    """`set_speed` (the offboard-loss tests run the vehicle's last seconds faster once the app is
    gone): at 1x, 4 s of vehicle time cannot pass in 1.5 s of wall time; at 20x they do; a
    lockstep mock has no pace to change."""
    import asyncio

    own = MockConfig(vehicle="fast", spawn=SpawnSpec.parse("hover:0,0,-2"), udp_local_port=0, udp_remote=None, speed=1.0)
    with run_in_thread(own) as mock:
        t0 = mock.call(lambda m: m.time_s)
        slow = asyncio.run_coroutine_threadsafe(mock.mock.wait_for(lambda m: m.time_s >= t0 + 4.0, 1.5), mock._loop).result(5.0)
        mock.call(lambda m: m.set_speed(20.0))
        t1 = mock.call(lambda m: m.time_s)
        fast = asyncio.run_coroutine_threadsafe(mock.mock.wait_for(lambda m: m.time_s >= t1 + 4.0, 1.5), mock._loop).result(5.0)
        with pytest.raises(ValueError, match="speed"):
            mock.call(lambda m: m.set_speed(float("nan")))
    assert not slow and fast
    lockstep = MockConfig(vehicle="fast", spawn=SpawnSpec.parse("hover:0,0,-2"), udp_local_port=0, udp_remote=None, lockstep=True)
    with run_in_thread(lockstep) as mock:
        with pytest.raises(ValueError, match="lockstep"):
            mock.call(lambda m: m.set_speed(2.0))
