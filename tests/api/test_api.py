"""The asyncio API over real loopback sockets against sitl-mock: the snippet end to end, each
exception class, two follows in one connection, leaving the block mid-flight, status()."""

from __future__ import annotations

import asyncio
import io

import pytest
from pymavlink.dialects.v20 import common as mavlink2
from sitl_mock.config import MockConfig, SpawnSpec
from sitl_mock.runner import run_in_thread

import pf_offboard
from faults.common import hover, lockstep, write_config
from pf_offboard.logs.tlog import read_tlog

pytestmark = pytest.mark.integration


def _url(mock) -> str:  # noqa: ANN001
    return f"udpout://127.0.0.1:{mock.ports.udp}"


def _mode(mock) -> str:  # noqa: ANN001
    return mock.call(lambda m: m.autopilot.mode.name)


def test_the_snippet_with_the_mavsdk_url_flies_end_to_end(tmp_path) -> None:
    """The README's snippet: connect on udp://:14540 (the mock sends there, as PX4 SITL does),
    take off, follow a config file for two laps, hand back; the mock ends in its hold mode."""
    config = write_config(tmp_path, rate_hz=50.0)  # the take-off's default rate: one lockstep step per setpoint
    cfg = MockConfig(vehicle="fast", profile="px4", spawn=SpawnSpec.parse("ground:-3,0"), udp_local_port=0,
                     udp_remote=("127.0.0.1", 14540), lockstep=True, lockstep_dt_s=0.02)  # fmt: skip
    printed = io.StringIO()

    async def snippet() -> pf_offboard.FollowResult:
        async with pf_offboard.connect("udp://:14540", status_stream=printed, quiet=True) as vehicle:
            await vehicle.takeoff(2.0)
            result = await vehicle.follow(str(config), laps=2)
            print(result.reason, result.cross_track_rms_m, result.speed_error_rms_m_s, file=printed)
            await vehicle.hand_back()
            return result

    with run_in_thread(cfg) as mock:
        result = asyncio.run(snippet())
        assert _mode(mock) == "AUTO.LOITER"
        assert mock.call(lambda m: m.autopilot.armed)
    assert result.ok and result.reason.startswith("2 laps done"), result.reason
    assert result.laps >= 2.0
    assert result.cross_track_rms_m is not None and result.cross_track_rms_m < 0.1
    assert result.speed_error_rms_m_s is not None and result.speed_error_rms_m_s < 0.2
    assert "2 laps done" in printed.getvalue()


def test_two_follows_in_one_connection_and_status(tmp_path) -> None:
    """Two paths in a row on one connection (each handed back, then engaged again), progress from
    status() while following, logs per follow."""
    config = write_config(tmp_path)
    seen: list[pf_offboard.Progress] = []

    async def fly(url: str) -> list[pf_offboard.FollowResult]:
        async with pf_offboard.connect(url, quiet=True, status_stream=io.StringIO()) as vehicle:

            async def watch() -> None:
                async for p in vehicle.status(period_s=0.05):
                    seen.append(p)

            watcher = asyncio.create_task(watch())
            first = await vehicle.follow(config, duration_s=1.0, log_dir=tmp_path / "one")
            second = await vehicle.follow(config, duration_s=1.0, speed=1.0, log_dir=tmp_path / "two")
            watcher.cancel()
            return [first, second]

    with run_in_thread(lockstep("px4", hover())) as mock:
        first, second = asyncio.run(fly(_url(mock)))
        assert _mode(mock) == "AUTO.LOITER"
    assert first.ok and second.ok
    assert "duration 1 s reached" in first.reason and "duration 1 s reached" in second.reason
    assert second.activation_time_s > first.activation_time_s
    for log in (tmp_path / "one", tmp_path / "two"):
        entries = read_tlog(log / "flight.tlog")
        modes = [e.message.param2 for e in entries if e.direction == "out" and e.message.get_type() == "COMMAND_LONG"
                 and e.message.command == mavlink2.MAV_CMD_DO_SET_MODE]  # fmt: skip
        assert modes[0] == 6 and modes[-1] == 4  # OFFBOARD, then the hand-back AUTO.LOITER
    following = [p for p in seen if p.phase == "following"]
    assert following and all(p.eta1_m is not None and p.cross_track_m is not None for p in following)
    assert any(p.mode == "OFFBOARD" and p.armed for p in following)


def test_leaving_the_block_mid_flight_hands_back_confirmed(tmp_path) -> None:
    """A follow still running when the program leaves the async with block: handed back in the
    hold mode (confirmed by the autopilot) before the connection closes."""
    config = write_config(tmp_path)
    results: list[object] = []

    async def fly(url: str) -> None:
        async with pf_offboard.connect(url, quiet=True, status_stream=io.StringIO()) as vehicle:
            task = asyncio.create_task(vehicle.follow(config))  # a closed path: no end of its own
            task.add_done_callback(lambda t: results.append(t.result() if not t.exception() else t.exception()))
            async for p in vehicle.status(period_s=0.02):
                if p.phase == "following" and p.laps > 0.05:
                    break
        await asyncio.sleep(0)

    with run_in_thread(lockstep("px4", hover())) as mock:
        asyncio.run(fly(_url(mock)))
        assert _mode(mock) == "AUTO.LOITER"
    assert len(results) == 1 and isinstance(results[0], pf_offboard.FollowResult), results
    assert results[0].ok and "left the connection's async with block; handed back in AUTO.LOITER" in results[0].reason


def _expect(exc_type: type[pf_offboard.FlightError], mock_config: MockConfig, config, **follow) -> pf_offboard.FlightError:  # noqa: ANN001
    async def fly(url: str) -> None:
        async with pf_offboard.connect(url, quiet=True, status_stream=io.StringIO()) as vehicle:
            await vehicle.follow(config, **follow)

    with run_in_thread(mock_config) as mock:
        with pytest.raises(exc_type) as info:
            asyncio.run(fly(_url(mock)))
    err = info.value
    assert isinstance(err, pf_offboard.FlightError) and err.exit_code == exc_type.exit_code
    return err


def test_operator_takeover(tmp_path) -> None:
    err = _expect(pf_offboard.OperatorTakeover, lockstep("px4", hover(), takeover_at_s=2.0, takeover_mode="POSCTL"), write_config(tmp_path))
    assert err.exit_code == 4 and "POSCTL" in str(err) and err.result.exit_code == 4 and err.result.activation_time_s is not None


def test_operator_takeover_during_takeoff(tmp_path) -> None:
    cfg = lockstep("px4", "ground", takeover_above_m=0.5, takeover_mode="POSCTL")
    cfg = MockConfig(**{**cfg.__dict__, "lockstep_dt_s": 0.02})  # the take-off streams at 50 Hz

    async def fly(url: str) -> None:
        async with pf_offboard.connect(url, quiet=True, status_stream=io.StringIO()) as vehicle:
            await vehicle.takeoff(2.0)

    with run_in_thread(cfg) as mock:
        with pytest.raises(pf_offboard.OperatorTakeover) as info:
            asyncio.run(fly(_url(mock)))
    assert "during takeoff" in str(info.value)


def test_envelope_breach(tmp_path) -> None:
    cfg = lockstep("px4", hover(), estimator_reset_at_s=2.0, estimator_reset_ned_m=(10.0, 0.0, 0.0))
    err = _expect(pf_offboard.EnvelopeBreach, cfg, write_config(tmp_path))
    assert err.exit_code == 5 and err.result.breach is not None and str(err).startswith("safety:")


def test_crash_detected(tmp_path) -> None:
    err = _expect(pf_offboard.CrashDetected, lockstep("px4", hover(), disarm_at_s=2.0), write_config(tmp_path))
    assert err.exit_code == 6 and "disarmed" in str(err)


def test_link_lost(tmp_path) -> None:
    config = write_config(tmp_path, safety={"heartbeat_timeout_s": 1.0, "safe_mode_timeout_s": 2.0})
    err = _expect(pf_offboard.LinkLost, lockstep("px4", hover(), heartbeat_mute_s=(2.0, 1000.0)), config)
    assert err.exit_code == 3 and "HEARTBEAT" in str(err)
    assert isinstance(err, pf_offboard.FlightError)


def test_no_autopilot_is_link_lost_on_connect() -> None:
    printed = io.StringIO()

    async def fly() -> None:
        async with pf_offboard.connect("udpin://127.0.0.1:14599", heartbeat_timeout_s=0.3, status_stream=printed):
            pass

    with pytest.raises(pf_offboard.LinkLost) as info:
        asyncio.run(fly())
    assert info.value.result is None and "no HEARTBEAT" in str(info.value)
    assert printed.getvalue().startswith("waiting for a HEARTBEAT on udpin:127.0.0.1:14599 (up to 0.3 s)")


def test_the_heartbeat_wait_says_how_long_it_has_waited() -> None:
    from pf_offboard.app.link import Link, parse_endpoint

    lines: list[str] = []

    async def wait() -> None:
        link = Link.open(parse_endpoint("udpin://127.0.0.1:14598"))
        try:
            await link.wait_heartbeat(0.45, announce=lines.append, progress_every_s=0.1)
        finally:
            link.close()

    with pytest.raises(pf_offboard.LinkError):
        asyncio.run(wait())
    assert lines[0] == "waiting for a HEARTBEAT on udpin:127.0.0.1:14598 (up to 0.45 s)"
    assert any(line.startswith("waiting for a HEARTBEAT on udpin:127.0.0.1:14598: ") and "s of up to 0.45 s" in line for line in lines[1:]), lines


@pytest.mark.parametrize("profile", ["px4", "ardupilot"])
def test_refused_offboard_or_guided_is_command_refused(tmp_path, profile: str) -> None:
    """The autopilot answers the switch to OFFBOARD / GUIDED with COMMAND_ACK DENIED."""
    config = write_config(tmp_path, output_mode="attitude")
    cfg = lockstep(profile, hover())

    def deny_offboard(m) -> None:  # noqa: ANN001
        original = m.autopilot._cmd_set_mode

        def patched(p: list[float]) -> tuple[int, list]:
            main = int(p[1])
            if (profile == "px4" and main == 6) or (profile == "ardupilot" and main == 4):
                return mavlink2.MAV_RESULT_DENIED, []
            return original(p)

        m.autopilot._cmd_set_mode = patched

    async def fly(url: str) -> None:
        async with pf_offboard.connect(url, quiet=True, status_stream=io.StringIO()) as vehicle:
            await vehicle.follow(config, duration_s=1.0, set_guid_options=True)

    with run_in_thread(cfg) as mock:
        mock.call(deny_offboard)
        with pytest.raises(pf_offboard.CommandRefused) as info:
            asyncio.run(fly(_url(mock)))
    err = info.value
    assert err.exit_code == 3 and "refused by the autopilot" in str(err) and err.result is not None


def test_autopilot_failsafe_is_a_flight_error_with_exit_7() -> None:
    assert issubclass(pf_offboard.AutopilotFailsafe, pf_offboard.FlightError)
    assert pf_offboard.AutopilotFailsafe("RTL", None).exit_code == 7
    codes = {c.exit_code for c in (pf_offboard.LinkLost, pf_offboard.OperatorTakeover, pf_offboard.EnvelopeBreach,
                                   pf_offboard.CrashDetected, pf_offboard.AutopilotFailsafe)}  # fmt: skip
    assert codes == {3, 4, 5, 6, 7}


def test_bad_input_is_a_typed_error_before_any_traffic(tmp_path) -> None:
    async def fly(url: str) -> None:
        async with pf_offboard.connect(url, quiet=True, status_stream=io.StringIO()) as vehicle:
            await vehicle.follow(write_config(tmp_path), laps=-1)

    with run_in_thread(lockstep("px4", hover())) as mock:
        with pytest.raises(pf_offboard.InputError) as info:
            asyncio.run(fly(_url(mock)))
        assert _mode(mock) == "AUTO.LOITER"
    assert info.value.field == "laps"

    async def bad_url() -> None:
        async with pf_offboard.connect("udp://localhost"):  # parsed on entering: before any socket opens
            pass

    with pytest.raises(pf_offboard.InputError) as info:
        asyncio.run(bad_url())
    assert info.value.field == "--connect"


def test_ardupilot_take_off_holds_in_guided_then_follows(tmp_path) -> None:
    """ArduPilot: take off (GUIDED, NAV_TAKEOFF) and stay in GUIDED, which holds the position by
    itself (its LOITER would follow the low RC throttle down); the next follow engages from there.
    The mock on its own clock (4x): ArduPilot climbs while we send nothing, which lockstep cannot."""
    config = write_config(tmp_path, rate_hz=50.0, output_mode="attitude")
    cfg = MockConfig(vehicle="fast", profile="ardupilot", spawn=SpawnSpec.parse("ground:-1.5,0"), udp_local_port=0,
                     udp_remote=None, speed=4.0)  # fmt: skip

    async def fly(url: str) -> tuple[pf_offboard.FollowResult, str, pf_offboard.FollowResult]:
        async with pf_offboard.connect(url, quiet=True, status_stream=io.StringIO()) as vehicle:
            took = await vehicle.takeoff(2.0)
            mode_after_takeoff = vehicle.progress().mode
            result = await vehicle.follow(config, duration_s=2.0, set_guid_options=True)
            return took, mode_after_takeoff, result

    with run_in_thread(cfg) as mock:
        took, mode, result = asyncio.run(fly(_url(mock)))
        assert _mode(mock) == "BRAKE"
    assert took.ok and "holding in GUIDED" in took.reason and mode == "GUIDED"
    assert result.ok and "duration 2 s reached; handed back in BRAKE" in result.reason
