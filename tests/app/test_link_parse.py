"""Endpoint parsing: every malformed --connect is one InputError naming the flag."""

import pytest

from pf_offboard.app.link import Endpoint, parse_endpoint
from pf_offboard.errors import InputError


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("udpin:0.0.0.0:14540", Endpoint("udpin", "0.0.0.0", 14540)),
        ("udpout:127.0.0.1:14580", Endpoint("udpout", "127.0.0.1", 14580)),
        ("tcp:localhost:5760", Endpoint("tcp", "localhost", 5760)),
        ("serial:/dev/ttyACM0:921600", Endpoint("serial", "/dev/ttyACM0", 921600)),
    ],
)
def test_valid_endpoints(text: str, expected: Endpoint) -> None:
    ep = parse_endpoint(text)
    assert ep == expected
    assert str(ep) == text


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        # MAVSDK URLs
        ("udp://:14540", Endpoint("udpin", "0.0.0.0", 14540)),
        ("udp://127.0.0.1:14540", Endpoint("udpin", "127.0.0.1", 14540)),
        ("udpin://0.0.0.0:14540", Endpoint("udpin", "0.0.0.0", 14540)),
        ("udpout://127.0.0.1:14580", Endpoint("udpout", "127.0.0.1", 14580)),
        ("tcp://127.0.0.1:5760", Endpoint("tcp", "127.0.0.1", 5760)),
        ("tcpin://:5760", Endpoint("tcpin", "0.0.0.0", 5760)),
        ("serial:///dev/ttyACM0:921600", Endpoint("serial", "/dev/ttyACM0", 921600)),
        # pymavlink / MAVProxy
        ("udp:127.0.0.1:14550", Endpoint("udpin", "127.0.0.1", 14550)),
        ("tcpin:0.0.0.0:5760", Endpoint("tcpin", "0.0.0.0", 5760)),
        ("/dev/ttyACM0,921600", Endpoint("serial", "/dev/ttyACM0", 921600)),
        ("/dev/ttyUSB0", Endpoint("serial", "/dev/ttyUSB0", 115200)),
    ],
)
def test_endpoints_as_users_write_them(text: str, expected: Endpoint) -> None:
    assert parse_endpoint(text) == expected


def test_mavutil_urls() -> None:
    assert parse_endpoint("udpin:0.0.0.0:14540").mavutil_url() == "udpin:0.0.0.0:14540"
    assert parse_endpoint("serial:/dev/ttyUSB0:57600").mavutil_url() == "/dev/ttyUSB0"


@pytest.mark.parametrize(
    ("text", "fragment"),
    [
        ("", "KIND:ADDRESS:PORT"),
        ("14540", "KIND:ADDRESS:PORT"),
        ("foo:127.0.0.1:14540", "unknown endpoint kind 'foo'"),
        ("http://127.0.0.1:14540", "unknown endpoint scheme 'http'"),
        ("udp://localhost", "expected udp://[HOST]:PORT"),
        ("udpout://:14540", "needs the HOST to send to"),
        ("serial:///dev/ttyACM0:fast", "baud rate 'fast'"),
        ("udpin:14540", "expected udpin:HOST:PORT"),
        ("udpin:127.0.0.1:", "expected udpin:HOST:PORT"),
        ("tcp:127.0.0.1:port", "port 'port' is not a positive integer"),
        ("tcp:127.0.0.1:0", "outside 1..65535"),
        ("tcp:127.0.0.1:70000", "outside 1..65535"),
        ("tcp:bad host:5760", "not a host name"),
        ("serial:/dev/ttyACM0:fast", "baud rate 'fast'"),
        ("serial:/dev/ttyACM0:0", "baud rate must be positive"),
    ],
)
def test_malformed_endpoints(text: str, fragment: str) -> None:
    with pytest.raises(InputError) as info:
        parse_endpoint(text)
    assert info.value.field == "--connect"
    assert fragment in info.value.reason


def test_fly_flags_and_flight_section(tmp_path) -> None:
    """Launch heights from the config, flag validation: InputError naming the flag, nothing opened."""
    import argparse

    import yaml

    from pf_offboard.app.fly import _check_args, _heights_from_config, add_arguments, flight_settings
    from pf_offboard.config import load_config

    parser = argparse.ArgumentParser()
    add_arguments(parser)
    data = yaml.safe_load(open("configs/paper.yaml"))
    data["flight"].update(takeoff_altitude_m=2.5, output_mode="rates", attitude_time_constant_s=0.05)
    path = tmp_path / "c.yaml"
    path.write_text(yaml.safe_dump(data))
    config = load_config(path)
    args = parser.parse_args(["--connect", "udpin:0.0.0.0:14540", "--config", str(path), "--takeoff"])
    _heights_from_config(args, config)
    assert args.takeoff == 2.5
    settings = flight_settings(config, args)
    assert (settings.output_mode, settings.attitude_time_constant_s, settings.end_action) == ("rates", 0.05, "hold")
    args = parser.parse_args(["--connect", "udpin:0.0.0.0:14540", "--config", str(path), "--throw"])
    with pytest.raises(InputError) as info:
        _heights_from_config(args, config)  # paper.yaml has no throw activation height
    assert info.value.field == "--throw"
    for flags, field in ((["--takeoff", "0.1"], "--takeoff"), (["--airborne", "--laps", "0"], "--laps"),
                         (["--airborne", "--duration", "nan"], "--duration"), (["--throw", "-1"], "--throw"),
                         (["--airborne", "--target-system", "0"], "--target-system"),
                         (["--airborne", "--target-system", "256"], "--target-system")):  # fmt: skip
        args = parser.parse_args(["--connect", "udpin:0.0.0.0:14540", "--config", str(path), *flags])
        with pytest.raises(InputError) as info:
            _heights_from_config(args, config)  # a typed height (even -1) is never "take it from the config"
            _check_args(args)
        assert info.value.field == field
    args = parser.parse_args(["--connect", "udpin:0.0.0.0:14540", "--config", str(path), "--airborne", "--output", "attitude"])
    assert flight_settings(config, args).output_mode == "attitude"  # the flag wins


@pytest.mark.parametrize("command", ["fly", "demo"])
def test_unwritable_log_dir_is_exit_2_before_connecting(tmp_path, command, capsys) -> None:
    """--log-dir that cannot be created: one line naming the flag, exit 2, nothing opened or spawned."""
    from pf_offboard.cli import main

    blocker = tmp_path / "file"
    blocker.write_text("")
    flags = ["--log-dir", str(blocker / "logs")]
    if command == "fly":  # nobody listens on this port: a link attempt would time out with exit 3
        flags += ["--connect", "udpin:127.0.0.1:9", "--config", "configs/paper.yaml", "--airborne", "--heartbeat-timeout", "0.01"]
    assert main([command, *flags]) == 2
    err = capsys.readouterr().err
    assert "--log-dir: cannot create directory" in err and "Traceback" not in err


def test_serial_endpoint_that_cannot_open_is_a_link_error() -> None:
    """A missing device, or pymavlink's optional pyserial missing: LinkError naming the endpoint (exit 3)."""
    import importlib.util

    from pf_offboard.app.link import Link
    from pf_offboard.errors import LinkError

    with pytest.raises(LinkError, match="cannot open serial:/dev/pf-offboard-no-such-device:57600") as info:
        Link.open(parse_endpoint("serial:/dev/pf-offboard-no-such-device:57600"))
    if importlib.util.find_spec("serial") is None:
        assert "pip install pyserial" in str(info.value)


@pytest.mark.parametrize(
    ("flight", "vehicle", "expected_s"),
    [({}, {}, 0.25), ({}, {"rate_time_constant_s": 0.05}, 0.2), ({"attitude_time_constant_s": 0.1}, {"rate_time_constant_s": 0.05}, 0.1)],
)  # fmt: skip
def test_rates_time_constant_default_derived_or_pinned(tmp_path, flight: dict, vehicle: dict, expected_s: float) -> None:
    """τ: the config's flight.attitude_time_constant_s if set; else 4 x vehicle.rate_time_constant_s;
    else the safe default 0.25 s (the old 0.05 s tumbled real PX4 and ArduPilot vehicles)."""
    import argparse

    import yaml

    from pf_offboard.app.fly import add_arguments, flight_settings
    from pf_offboard.config import load_config

    data = yaml.safe_load(open("configs/paper.yaml"))
    data["flight"].update(output_mode="rates", **flight)
    if vehicle:
        data["vehicle"] = vehicle
    path = tmp_path / "c.yaml"
    path.write_text(yaml.safe_dump(data))
    parser = argparse.ArgumentParser()
    add_arguments(parser)
    args = parser.parse_args(["--connect", "udpin:0.0.0.0:14540", "--config", str(path), "--airborne"])
    assert flight_settings(load_config(path), args).attitude_time_constant_s == pytest.approx(expected_s)


def test_ready_and_takeoff_timeouts_are_validated() -> None:
    import argparse

    from pf_offboard.app.fly import _check_args, add_arguments

    parser = argparse.ArgumentParser()
    add_arguments(parser)
    args = parser.parse_args(["--connect", "udpin:0.0.0.0:14540", "--config", "x.yaml", "--takeoff", "2"])
    assert args.ready_timeout == 120.0 and args.takeoff_timeout is None and args.command_timeout == 5.0
    _check_args(args)
    for flag in ("--ready-timeout", "--takeoff-timeout", "--command-timeout"):
        for bad in ("0", "nan", "-5"):
            args = parser.parse_args(["--connect", "udpin:0.0.0.0:14540", "--config", "x.yaml", "--takeoff", "2", flag, bad])
            with pytest.raises(InputError) as info:
                _check_args(args)
            assert info.value.field == flag
