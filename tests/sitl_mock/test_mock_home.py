"""The mock's home: configurable (--home), sent as HOME_POSITION and GPS_GLOBAL_ORIGIN like PX4 /
ArduPilot, and answered on MAV_CMD_REQUEST_MESSAGE once the position estimate is ready."""

from __future__ import annotations

import pytest
from pymavlink.dialects.v20 import common as mavlink

from sitl_mock.autopilot import Autopilot
from sitl_mock.cli import build_parser, config_from_args, config_to_args, main
from sitl_mock.config import MockConfig
from sitl_mock.profiles import PROFILES
from sitl_mock.testing import command_long

CANBERRA = (-35.363261, 149.165230, 584.0)


def _config(*argv: str) -> MockConfig:
    return config_from_args(build_parser().parse_args(list(argv)))


def test_home_flag_sets_and_round_trips() -> None:
    c = _config("--home=-35.363261,149.16523,584")
    assert (c.home_lat_deg, c.home_lon_deg, c.home_alt_m) == CANBERRA
    assert _config(*config_to_args(c)) == c
    default = _config()
    assert (default.home_lat_deg, default.home_lon_deg, default.home_alt_m) == (47.397742, 8.545594, 488.0)


@pytest.mark.parametrize("value", ["91,0,0", "0,181,0", "1,2", "a,b,c", "0,0,20000"])
def test_bad_home_is_exit_2_naming_the_flag(value: str, capsys) -> None:
    assert main(["--home=" + value]) == 2
    assert "--home" in capsys.readouterr().err


def _request(ap: Autopilot, msgid: int) -> list:
    return ap.handle(command_long(mavlink.MAV_CMD_REQUEST_MESSAGE, msgid), 0)


def _run(ap: Autopilot, seconds: float) -> None:
    for _ in range(int(seconds / 0.004)):
        ap.step(0.004)


@pytest.mark.parametrize("profile", ["px4", "ardupilot"])
def test_request_message_answers_origin_and_home(profile: str) -> None:
    ap = Autopilot(MockConfig(vehicle="fast", profile=profile, home_lat_deg=CANBERRA[0], home_lon_deg=CANBERRA[1], home_alt_m=CANBERRA[2]))
    _run(ap, 1.0)  # past the position-estimate delay (0.5 s)
    for msgid, kind in ((mavlink.MAVLINK_MSG_ID_GPS_GLOBAL_ORIGIN, "GPS_GLOBAL_ORIGIN"), (mavlink.MAVLINK_MSG_ID_HOME_POSITION, "HOME_POSITION")):
        replies = [m for _, m in _request(ap, msgid)]
        assert replies[0].get_type() == "COMMAND_ACK" and replies[0].result == mavlink.MAV_RESULT_ACCEPTED
        msg = replies[1]
        assert msg.get_type() == kind
        assert (msg.latitude, msg.longitude, msg.altitude) == (-353632610, 1491652300, 584000)


def test_ardupilot_has_no_origin_before_its_ekf() -> None:
    ap = Autopilot(MockConfig(vehicle="fast", profile="ardupilot"))
    replies = [m for _, m in _request(ap, mavlink.MAVLINK_MSG_ID_GPS_GLOBAL_ORIGIN)]
    assert len(replies) == 1 and replies[0].result == mavlink.MAV_RESULT_FAILED


def test_px4_streams_origin_and_home() -> None:
    streams = dict(PROFILES["px4"].streams)
    assert streams[mavlink.MAVLINK_MSG_ID_GPS_GLOBAL_ORIGIN] == pytest.approx(0.1)
    assert streams[mavlink.MAVLINK_MSG_ID_HOME_POSITION] == pytest.approx(0.5)
    ap = Autopilot(MockConfig(vehicle="fast", profile="px4"))
    ap.add_link(0)
    seen = set()
    for _ in range(int(10.5 / 0.004)):
        ap.step(0.004)
        seen |= {m.get_type() for _, m in ap.due_telemetry()}
    assert {"GPS_GLOBAL_ORIGIN", "HOME_POSITION"} <= seen
