"""The hold the app hands ArduCopter to holds without a pilot at the sticks. Measured on ArduCopter
SITL: handed back in LOITER (exit 0), the vehicle descended from 1.8 m and hit the ground at
2.4 m/s 1.5 s later, because LOITER climbs and descends with the RC throttle stick and the SITL's
RC input with nobody at the sticks is stick fully down (as a pilot's is after a GUIDED take-off).
The hold is BRAKE now, which ignores the sticks (the pilot takes over by switching mode). Against
sitl-mock over real loopback UDP, the vehicle watched after the app has gone."""

from __future__ import annotations

import asyncio
import dataclasses

import pytest
from sitl_mock.runner import run_in_thread
from sitl_mock.testing import free_udp_port

from .attackers import fly_udpin
from .common import own_clock, write_config

pytestmark = pytest.mark.integration


def _mock_time_passes(mock, seconds: float) -> None:
    t_end = mock.call(lambda m: m.time_s) + seconds
    fut = asyncio.run_coroutine_threadsafe(mock.mock.wait_for(lambda m: m.time_s >= t_end, 60.0), mock._loop)
    assert fut.result(65.0)


def test_ardupilot_hand_back_holds_with_the_throttle_stick_down(tmp_path) -> None:
    app_port = free_udp_port()
    config = write_config(tmp_path)
    cfg = own_clock("ardupilot", "hover:-3.0,0.0,-2.0", tmp_path / "truth.csv", speed=1.0)
    cfg = dataclasses.replace(cfg, udp_remote=("127.0.0.1", app_port))
    with run_in_thread(cfg) as mock:

        def on_start(flight) -> None:
            original = flight._activate

            def activate() -> None:  # the pilot's throttle stick is down from here on (as after a GUIDED take-off)
                original()
                mock.call(lambda m: setattr(m.autopilot, "rc_throttle", 0.0))

            flight._activate = activate

        outcome, printed = fly_udpin(app_port, config, tmp_path / "log", "--airborne", "--duration", "3", "--output", "attitude",
                                     "--set-guid-options", on_start=on_start)  # fmt: skip
        alt_at_exit = mock.call(lambda m: -float(m.truth.position_ned_m[2]))
        mock.call(lambda m: m.set_speed(8.0))  # the app has exited: the vehicle's next 4 s pass in 0.5 s
        _mock_time_passes(mock, 4.0)
        mode, armed, alt = mock.call(lambda m: (m.autopilot.mode.name, bool(m.autopilot.armed), -float(m.truth.position_ned_m[2])))
    print(f"\nhand-back with the throttle stick down: exit {outcome.exit_code}, {outcome.reason}; {mode} armed={armed}, "
          f"{alt_at_exit:.2f} m at exit, {alt:.2f} m 4 s later")  # fmt: skip
    assert outcome.exit_code == 0, printed
    assert "handed back in BRAKE" in outcome.reason
    assert (mode, armed) == ("BRAKE", True)
    assert alt > alt_at_exit - 0.3 and alt > 1.0  # held its height (LOITER: down to the ground)
