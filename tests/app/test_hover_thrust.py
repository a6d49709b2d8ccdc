"""The hover thrust attitude / rates output fly with: measured from the autopilot's own attitude
target while it holds (app/hover.py), where its parameter is not what it flies (PX4)."""

from __future__ import annotations

import numpy as np
import pytest
from sitl_mock.config import MockConfig, SpawnSpec
from sitl_mock.runner import run_in_thread

from pf_offboard.app.hover import MAX_SPREAD, MIN_SAMPLES, STILL_SPEED_M_S, WINDOW_S, HoverThrustMeter
from pf_offboard.logs.tlog import read_tlog

from .flights import RATE_HZ, run_fly, write_config

HOVER_NED = (-3.0, 0.0, -2.0)  # 1.5 m off the paper path (as test_fly_integration)
FAST_HOVER = 1.0 / 3.5  # the "fast" preset's true hover throttle (thrust-to-weight 3.5)


def test_the_median_of_a_still_window_is_the_hover_thrust() -> None:
    m = HoverThrustMeter()
    for k in range(20):  # 10 Hz, still, a little noise around 0.61
        m.add(0.1 * k, 0.61 + (0.01 if k % 2 else -0.01), 0.05)
    assert 0.6 <= m.hover_thrust() <= 0.62
    c = HoverThrustMeter()
    for k in range(20):
        c.add(0.1 * k, 0.61, 0.05)
    assert c.hover_thrust() == pytest.approx(0.61, abs=1e-12)
    # only the newest WINDOW_S count: a sample later than that replaces the window
    m.add(1.9 + WINDOW_S + 0.2, 0.7, 0.0)
    assert m.hover_thrust() is None  # one sample


def test_no_value_while_moving_too_few_or_spread_samples() -> None:
    m = HoverThrustMeter()
    for k in range(20):
        m.add(0.1 * k, 0.6, 0.05)
    m.add(2.0, 0.6, STILL_SPEED_M_S + 0.1)  # moving: the window starts again
    assert m.hover_thrust() is None
    for k in range(MIN_SAMPLES - 1):
        m.add(2.1 + 0.1 * k, 0.6, 0.0)
    assert m.hover_thrust() is None  # too few
    m.add(2.5, 0.6, 0.0)
    assert m.hover_thrust() == pytest.approx(0.6)
    s = HoverThrustMeter()
    for k in range(10):  # climbing and sinking: not one hover
        s.add(0.1 * k, 0.5 + (MAX_SPREAD if k % 2 else 0.0) + 0.01, 0.1)
    assert s.hover_thrust() is None
    for bad in (float("nan"), 0.99, 0.01):  # not finite: starts again; implausible: no value
        b = HoverThrustMeter()
        for k in range(10):
            b.add(0.1 * k, bad, 0.0)
        assert b.hover_thrust() is None, bad
    assert HoverThrustMeter().hover_thrust() is None
    j = HoverThrustMeter()
    for k in range(5):
        j.add(10.0 + 0.1 * k, 0.6, 0.0)
    j.add(1.0, 0.6, 0.0)  # the autopilot's clock jumped back: the window starts again
    assert j.hover_thrust() is None
    n = HoverThrustMeter()
    n.add(0.0, 0.6, None)  # no state yet: not known to be still
    assert n.hover_thrust() is None


def _fly(tmp_path, profile: str, output: str, reported: float, **flight: object):
    """--airborne on a "fast" mock (true hover 1/3.5) whose hover-thrust parameter reads
    ``reported``; ``flight``: the config's flight: section; (outcome, the thrusts sent from the
    mode switch on, the events logged while following)."""
    tmp_path.mkdir(parents=True, exist_ok=True)
    config = write_config(tmp_path, **flight)
    cfg = MockConfig(vehicle="fast", profile=profile, spawn=SpawnSpec.parse("hover:" + ",".join(map(str, HOVER_NED))),
                     udp_local_port=0, udp_remote=None, lockstep=True, lockstep_dt_s=1.0 / RATE_HZ)  # fmt: skip
    with run_in_thread(cfg) as mock:
        param = mock.call(lambda m: m.autopilot.profile.hover_param)
        mock.call(lambda m: m.autopilot.params.update({param: reported}))  # reported only: the vehicle is unchanged
        guid = ("--set-guid-options",) if profile == "ardupilot" else ()
        outcome = run_fly(mock.ports.udp, config, tmp_path / "log", "--airborne", "--output", output, "--duration", "3", *guid)
    assert outcome.exit_code == 0, outcome.reason
    out = [e.message for e in read_tlog(tmp_path / "log" / "flight.tlog") if e.direction == "out"]
    mode = next(i for i, m in enumerate(out) if m.get_type() == "COMMAND_LONG" and m.command == 176)  # the switch to OFFBOARD / GUIDED
    sent = [m for m in out[mode:] if m.get_type() == "SET_ATTITUDE_TARGET"]  # (before it: ignored, in hold)
    events = [r.event for r in outcome.records if r.active and r.event]
    return outcome, np.array([m.thrust for m in sent]), ";".join(events)


def _settling_error_m(outcome) -> float:
    """Cross-track RMS from 1 s after activation to the end: the approach's tail (the hover
    spawn is 1.5 m off the path)."""
    recs = [r for r in outcome.records if r.active]
    t0 = recs[0].time_s
    return float(np.sqrt(np.mean([r.cross_track_m**2 for r in recs if r.time_s >= t0 + 1.0])))


@pytest.mark.integration
@pytest.mark.parametrize("output", ["attitude", "rates"])
def test_px4_flies_the_hover_thrust_its_attitude_target_shows_not_the_parameter(tmp_path, output: str) -> None:
    """PX4's MPC_THR_HOVER reads 0.4, its own hold flies the vehicle's 0.286: the app measures
    0.286 from ATTITUDE_TARGET before activation, logs it with the activation and scales its
    thrusts by it from the first setpoint; with the parameter's value given in the config instead
    (flight.hover_thrust: 0.4, flown as given) the same first command goes out 40 % stronger and
    the approach's tail is 1.6-1.8 times as far off the path."""
    measured, thrust, event = _fly(tmp_path / "m", "px4", output, 0.4)
    assert "hover_thrust_measured=" in event, event
    value = float(event.split("hover_thrust_measured=")[1].split(";")[0])
    assert abs(value - FAST_HOVER) < 0.01, event
    given, thrust_given, event_given = _fly(tmp_path / "g", "px4", output, 0.4, hover_thrust=0.4)
    assert "hover_thrust_measured" not in event_given
    # the same first command (the same state at activation, lockstep) scaled by each hover thrust
    assert thrust[0] / thrust_given[0] == pytest.approx(value / 0.4, rel=0.01), (thrust[0], thrust_given[0])
    e, e_given = _settling_error_m(measured), _settling_error_m(given)
    print(f"\n{output}: hover measured {value:.3f} (true {FAST_HOVER:.3f}); cross-track RMS from activation + 1 s "
          f"{e * 100:.1f} cm, with the parameter's 0.4 {e_given * 100:.1f} cm")  # fmt: skip
    assert e < 0.7 * e_given  # measured: 0.55-0.61


@pytest.mark.integration
def test_ardupilot_reads_its_learned_parameter(tmp_path) -> None:
    """ArduCopter learns MOT_THST_HOVER in flight: it is flown as read, nothing measured."""
    outcome, _, event = _fly(tmp_path, "ardupilot", "attitude", FAST_HOVER)
    assert "hover_thrust_measured" not in event and event.startswith("activated"), event
