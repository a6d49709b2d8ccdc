"""``sitl-mock`` flags: parsing, round trip to a subprocess, clear errors with exit code 2."""

from __future__ import annotations

import csv
import subprocess
import sys

import pytest

from sitl_mock.cli import build_parser, config_from_args, config_to_args, main
from sitl_mock.config import FaultConfig, MockConfig, SpawnSpec


def _config(*argv: str) -> MockConfig:
    return config_from_args(build_parser().parse_args(list(argv)))


def test_defaults_like_px4_sitl_and_ardupilot_sitl() -> None:
    px4 = _config()
    assert (px4.udp_local_port, px4.udp_remote, px4.tcp_port) == (14580, ("127.0.0.1", 14540), None)
    ap = _config("--profile", "ardupilot")
    assert (ap.udp_local_port, ap.tcp_port) == (None, 5760)


def test_fault_and_spawn_flags() -> None:
    c = _config("--spawn", "throw:0,0,-2,3,0,-4", "--loss", "10", "--latency", "20", "--jitter", "5",
                "--blackout", "3,4", "--estimator-reset", "5,1,2,0", "--takeover", "6,AUTO.LAND",
                "--gust", "2,4,0,0,0.5", "--lockstep", "--seed", "9")
    assert c.spawn == SpawnSpec("throw", (0.0, 0.0, -2.0), (3.0, 0.0, -4.0))
    f = c.faults
    assert (f.loss, f.latency_s, f.jitter_s, f.blackout_s) == (0.1, 0.02, 0.005, (3.0, 4.0))
    assert (f.estimator_reset_at_s, f.estimator_reset_ned_m) == (5.0, (1.0, 2.0, 0.0))
    assert (f.takeover_at_s, f.takeover_mode) == (6.0, "AUTO.LAND")
    assert (f.gust_at_s, f.gust_ned_m_s, f.gust_duration_s) == (2.0, (4.0, 0.0, 0.0), 0.5)
    assert c.lockstep and c.seed == 9


def test_config_round_trips_through_flags() -> None:
    config = MockConfig(profile="ardupilot", vehicle="px4-default", udp_local_port=0, udp_remote=None, tcp_port=0,
                        speed=5.0, spawn=SpawnSpec("hover", (1.0, 2.0, -3.0)), seed=4, duration_s=2.5,
                        faults=FaultConfig(loss=0.25, duplicate=0.01, corrupt=0.02, blackout_s=(1.0, 2.0),
                                           takeover_at_s=3.0, takeover_mode="BRAKE", loss_from_offboard=True),
                        params=(("ANGLE_MAX", 2500.0), ("PSC_ANGLE_MAX", 20.0)))
    assert _config(*config_to_args(config)) == config
    assert _config("--param", "MPC_TILTMAX_AIR=30").params == (("MPC_TILTMAX_AIR", 30.0),)


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--loss", "150"], "--loss"),
        (["--spawn", "hover:1,2"], "spawn"),
        (["--spawn", "hover:0,0,5"], "z must be <= 0"),
        (["--lockstep", "--speed", "3"], "--speed"),
        (["--speed", "0"], "speed"),
        (["--udp-remote", "10.0.0.1:14540"], "loopback"),
        (["--takeover", "1,GUIDED"], "unknown for px4"),
        (["--blackout", "5"], "--blackout"),
        (["--seed", "-1"], "seed"),
        (["--param", "MPC_TILTMAX_AIR"], "--param"),
        (["--param", "MPC_TILTMAX_AIR=abc"], "--param"),
        (["--param", "NO_SUCH_PARAM=1"], "params[0]"),
        (["--duration", "nan"], "duration"),
        (["--duration", "inf"], "duration"),
        (["--speed", "nan"], "speed"),
        (["--spawn", "hover:nan,0,-2"], "finite"),
        (["--loss", "nan"], "--loss"),
        (["--gust", "2,nan,0,0,0.5"], "--gust"),
        (["--udp-remote", "127.0.0.1:99999"], "port out of range"),
    ],
)
def test_bad_flags_exit_2_with_one_clear_line(argv: list[str], message: str, capsys) -> None:
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("sitl-mock: error:") and message in err and "\n" not in err


def test_argparse_errors_exit_2() -> None:
    result = subprocess.run([sys.executable, "-m", "sitl_mock", "--profile", "inav"], capture_output=True, text=True)
    assert result.returncode == 2 and "invalid choice" in result.stderr


@pytest.mark.integration
def test_duration_runs_and_writes_truth_log(tmp_path) -> None:
    log = tmp_path / "truth.csv"
    result = subprocess.run(
        [sys.executable, "-m", "sitl_mock", "--vehicle", "fast", "--udp-local", "0", "--udp-remote", "none", "--speed", "20",
         "--duration", "1.0", "--spawn", "throw:0,0,-30,2,0,0", "--truth-log", str(log), "--print-ports"],
        capture_output=True, text=True, timeout=60,
    )
    assert result.returncode == 0, result.stderr
    rows = list(csv.DictReader(log.open()))
    assert float(rows[-1]["time_s"]) == pytest.approx(1.0, abs=0.005)
    assert float(rows[-1]["vz_m_s"]) > 8.0  # ballistic: motors locked until commanded
    assert rows[0]["armed"] == "1" and rows[0]["mode"] == "AUTO.LOITER"


@pytest.mark.integration
def test_spawned_mock_stops_cleanly_and_flushes_the_truth_log(tmp_path) -> None:
    from sitl_mock.runner import spawn

    log = tmp_path / "truth.csv"
    config = MockConfig(udp_local_port=0, udp_remote=None, lockstep=True, truth_log=str(log))
    handle = spawn(config)
    assert handle.stop() == 0  # SIGTERM → clean shutdown, exit code 0
    assert log.read_text().startswith("time_s,")


@pytest.mark.parametrize(
    ("changes", "field"),
    [
        ({"udp_remote": ("10.0.0.1", 14540)}, "udp_remote"),
        ({"udp_remote": ("127.0.0.1", 0)}, "udp_remote"),
        ({"seed": -3}, "seed"),
        ({"seed": 1.5}, "seed"),
        ({"duration_s": float("inf")}, "duration_s"),
        ({"speed": float("nan")}, "speed"),
    ],
)
def test_python_api_config_is_validated_like_the_flags(changes: dict, field: str) -> None:
    from sitl_mock.config import MockConfigError

    with pytest.raises(MockConfigError, match=field):
        MockConfig(**changes).validate()


@pytest.mark.parametrize(
    ("changes", "field"),
    [
        ({"spawn": SpawnSpec("hover", (float("nan"), 0.0, -1.0))}, "spawn.position_ned_m"),
        ({"spawn": SpawnSpec("throw", (0.0, 0.0, -1.0), (0.0, float("inf"), 0.0))}, "spawn.velocity_ned_m_s"),
        ({"spawn": SpawnSpec("hover", (0.0, 0.0, 5.0))}, "spawn.position_ned_m"),
        ({"spawn": SpawnSpec("orbit")}, "spawn"),
        ({"home_lat_deg": float("nan")}, "home"),
        ({"faults": FaultConfig(gust_at_s=float("nan"))}, "faults.gust_at_s"),
        ({"faults": FaultConfig(takeover_at_s=-1.0)}, "faults.takeover_at_s"),
        ({"faults": FaultConfig(estimator_reset_at_s=float("inf"))}, "faults.estimator_reset_at_s"),
    ],
)
def test_python_api_spawn_home_and_fault_times_are_validated(changes: dict, field: str) -> None:
    from sitl_mock.config import MockConfigError

    with pytest.raises(MockConfigError) as err:
        MockConfig(**changes).validate()
    assert err.value.field == field
