"""Conformance with the real MAVSDK package (v4 native API) against the px4 profile over UDP."""

from __future__ import annotations

import asyncio
import math

import pytest

from sitl_mock.config import MockConfig
from sitl_mock.server import MockAutopilot
from sitl_mock.testing import free_udp_port

mavsdk_asyncio = pytest.importorskip("mavsdk.asyncio")
from mavsdk.asyncio import ComponentType, Configuration, Mavsdk  # noqa: E402
from mavsdk.asyncio.plugins.action import ActionAsync  # noqa: E402
from mavsdk.asyncio.plugins.offboard import AccelerationNed, AttitudeRate, OffboardAsync  # noqa: E402
from mavsdk.asyncio.plugins.telemetry import FlightMode, TelemetryAsync  # noqa: E402

pytestmark = pytest.mark.integration


async def _first(gen):
    async for item in gen:
        return item
    raise AssertionError("stream ended")


async def _sim_wait(mock: MockAutopilot, seconds: float) -> None:
    t0 = mock.time_s
    assert await mock.wait_for(lambda m: m.time_s >= t0 + seconds, timeout_s=30.0)


def test_mavsdk_connects_arms_and_flies_offboard() -> None:
    async def scenario() -> None:
        port = free_udp_port()
        # speed 2: PX4 scales the offboard-loss timeout with the speed factor, MAVSDK resends at 20 Hz.
        config = MockConfig(vehicle="fast", udp_local_port=0, udp_remote=("127.0.0.1", port), speed=2.0)
        async with MockAutopilot(config) as mock:
            sdk_config = Configuration.create_with_component_type(ComponentType.GROUND_STATION)
            async with Mavsdk(sdk_config) as sdk:
                await sdk.add_any_connection(f"udpin://127.0.0.1:{port}")
                drone = await sdk.first_autopilot(timeout_s=10.0)
                assert drone is not None
                telemetry, action, offboard = TelemetryAsync(drone), ActionAsync(drone), OffboardAsync(drone)

                position = await asyncio.wait_for(_first(telemetry.subscribe_position()), 10)
                assert position.latitude_deg == pytest.approx(47.397742, abs=1e-5)
                assert position.longitude_deg == pytest.approx(8.545594, abs=1e-5)
                assert position.absolute_altitude_m == pytest.approx(488.0, abs=0.1)
                euler = await asyncio.wait_for(_first(telemetry.subscribe_attitude_euler()), 10)
                assert abs(euler.roll_deg) < 1 and abs(euler.pitch_deg) < 1
                assert await asyncio.wait_for(_first(telemetry.subscribe_flight_mode()), 10) == FlightMode.HOLD
                assert await asyncio.wait_for(_first(telemetry.subscribe_armed()), 10) is False
                # The canonical MAVSDK example waits for this before arming.
                async def ready() -> None:
                    async for health in telemetry.subscribe_health():
                        if health.is_global_position_ok and health.is_home_position_ok and health.is_armable:
                            return

                await asyncio.wait_for(ready(), 10)

                await action.arm()
                assert mock.autopilot.armed
                assert await asyncio.wait_for(_first(telemetry.subscribe_armed()), 10) is True

                # Acceleration setpoints: 2 m/s² up (NED down = -2).
                await offboard.set_acceleration_ned(AccelerationNed(0.0, 0.0, -2.0))
                await offboard.start()
                assert mock.autopilot.mode.name == "OFFBOARD"
                await _sim_wait(mock, 1.5)
                assert mock.truth.velocity_ned_m_s[2] < -1.5
                assert mock.truth.position_ned_m[2] < -1.0
                # As commanded: the thrust acceleration (kinematic plus linear drag) is the setpoint.
                drag = mock.autopilot.sim.params.drag_1_s
                thrust_acc = mock.truth.accel_ned_m_s2 + drag * mock.truth.velocity_ned_m_s
                print("MAVSDK acceleration setpoint (0, 0, -2): thrust acceleration", thrust_acc)
                assert thrust_acc == pytest.approx([0.0, 0.0, -2.0], abs=0.05)
                modes = telemetry.subscribe_flight_mode()
                assert await asyncio.wait_for(_first(modes), 10) == FlightMode.OFFBOARD

                # Attitude-rate setpoints: yaw at 45 deg/s with hover thrust.
                hover = mock.autopilot.sim.params.true_hover_thrust
                await offboard.set_attitude_rate(AttitudeRate(0.0, 0.0, 45.0, hover))
                await _sim_wait(mock, 1.0)
                assert mock.truth.rates_frd_rad_s[2] == pytest.approx(math.radians(45.0), abs=0.1)
                assert abs(mock.truth.rates_frd_rad_s[0]) < 0.1 and abs(mock.truth.rates_frd_rad_s[1]) < 0.1
                # Hover thrust, level: no vertical thrust acceleration beyond drag; heading turns at 45 deg/s.
                thrust_acc = mock.truth.accel_ned_m_s2 + drag * mock.truth.velocity_ned_m_s
                print("MAVSDK attitude rate (0, 0, 45 deg/s, hover): thrust acceleration", thrust_acc)
                assert abs(thrust_acc[2]) < 0.1
                yaw0, t0 = mock.truth.euler_rad[2], mock.time_s
                await _sim_wait(mock, 0.5)
                turned = math.remainder(mock.truth.euler_rad[2] - yaw0, 2 * math.pi)
                assert turned / (mock.time_s - t0) == pytest.approx(math.radians(45.0), rel=0.05)

                await offboard.stop()
                assert mock.autopilot.mode.name == "AUTO.LOITER"

    asyncio.run(scenario())


def test_mavsdk_takeoff_and_land() -> None:
    async def scenario() -> None:
        port = free_udp_port()
        config = MockConfig(vehicle="fast", udp_local_port=0, udp_remote=("127.0.0.1", port), speed=5.0)
        async with MockAutopilot(config) as mock:
            sdk_config = Configuration.create_with_component_type(ComponentType.GROUND_STATION)
            async with Mavsdk(sdk_config) as sdk:
                await sdk.add_any_connection(f"udpin://127.0.0.1:{port}")
                drone = await sdk.first_autopilot(timeout_s=10.0)
                action = ActionAsync(drone)
                await action.arm()
                assert await action.get_takeoff_altitude() == pytest.approx(2.5)  # MIS_TAKEOFF_ALT
                await action.takeoff()
                await _sim_wait(mock, 6.0)
                assert mock.autopilot.mode.name == "AUTO.LOITER"  # takeoff done → hold
                assert mock.truth.position_ned_m[2] == pytest.approx(-2.5, abs=0.3)
                await action.land()
                await _sim_wait(mock, 8.0)
                assert mock.truth.landed and not mock.autopilot.armed  # landed → auto-disarm

    asyncio.run(scenario())
