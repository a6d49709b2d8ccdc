"""Estimator health against sitl-mock over real loopback UDP: one corrupt state sample never decides
a flight; a lost estimate (ODOMETRY quality -1 / estimator reports without a position solution,
drifting) is never flown on."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from sitl_mock.config import FaultConfig
from sitl_mock.runner import run_in_thread
from sitl_mock.testing import free_udp_port

from app.flights import write_config
from pf_offboard.app.fly import envelope_fence
from pf_offboard.config import load_config
from pf_offboard.frames import ned_to_enu

from .attackers import fly_udpin, mock_config
from .common import read_truth

pytestmark = pytest.mark.integration


def _end(mock) -> tuple[str, bool, np.ndarray, list[str]]:
    return mock.call(lambda m: (m.autopilot.mode.name, bool(m.autopilot.armed), ned_to_enu(np.array(m.truth.position_ned_m)),
                                [e.text for e in m.autopilot.log]))  # fmt: skip


def test_one_corrupt_sample_does_not_decide_the_flight(tmp_path) -> None:
    """At 2 s x jumps 40 m with vx = 5000 m/s (the sample excusing its own jump); at 3 s one sample
    says vz = +50 m/s (falling). Both refused as beyond the vehicle's limits: the flight completes
    (it ended on them with exit 5 / exit 6)."""
    app_port = free_udp_port()
    config = write_config(tmp_path)
    faults = FaultConfig(corrupt_states=((2.0, 40.0, 0.0, 0.0, 5000.0, 0.0, 0.0), (3.0, 0.0, 0.0, 0.0, 0.0, 0.0, 50.0)))
    for source in ("local_position", "odometry"):
        with run_in_thread(mock_config(app_port, faults=faults)) as mock:
            outcome, printed = fly_udpin(app_port, config, tmp_path / source, "--airborne", "--duration", "4", "--state-source", source)
            mode, armed, _, events = _end(mock)
        assert outcome.exit_code == 0, printed
        assert "duration 4 s reached; handed back in AUTO.LOITER" in outcome.reason
        assert (mode, armed) == ("AUTO.LOITER", True)
        assert sum("corrupt state sample sent" in e for e in events) == 2
        assert outcome.estimator.rejected_jumps == 2 and outcome.estimator.position_resets == 0, outcome.estimator.last_event


def test_a_lost_estimate_is_not_flown(tmp_path) -> None:
    """At 2 s the estimate is lost and drifts at 0.6 m/s (ODOMETRY quality -1; estimator reports
    without a position solution). Its samples are refused, following ends (the state goes stale), the
    hold is confirmed; the vehicle stays inside the fence (before: 19 s flown, 7.9 m outside)."""
    app_port = free_udp_port()
    config = write_config(tmp_path)
    fence = envelope_fence(load_config(config))
    faults = FaultConfig(estimate_lost_at_s=2.0)
    for source in ("odometry", "local_position"):
        with run_in_thread(mock_config(app_port, faults=faults)) as mock:
            outcome, printed = fly_udpin(app_port, config, tmp_path / source, "--airborne", "--duration", "8", "--state-source", source)
            mode, armed, position_enu, events = _end(mock)
        print(f"\nestimate lost ({source}): exit {outcome.exit_code}, {outcome.reason}; vehicle {mode} at {position_enu.round(2)}")
        assert outcome.exit_code == 3, printed
        assert "AUTO.LOITER requested, confirmed" in outcome.reason, outcome.reason
        assert "the estimate is refused: " in outcome.reason  # says why the state went stale
        assert (mode, armed) == ("AUTO.LOITER", True)
        assert not any("RTL" in e for e in events), events
        assert fence.violation(position_enu) == "", position_enu
        est = outcome.estimator
        assert est.rejected_unhealthy > 0
        last = [r for r in outcome.records if r.active][-1]
        assert last.time_s < 3.5  # nothing flown long after the loss


def test_a_vertical_estimator_reset_never_takes_the_vehicle_below_the_floor(tmp_path) -> None:
    """At 3 s the altitude estimate jumps 1.6 m up (the vehicle does not move). Followed, the app
    flew the real vehicle 1.6 m down: 0.03 m above the ground at path speed, exit 0. Now the reset
    (confirmed by the next sample) ends following on that sample: hold confirmed, exit 5, and the
    true altitude never drops below the fence floor."""
    app_port = free_udp_port()
    config = write_config(tmp_path)
    fence = envelope_fence(load_config(config))
    truth_log = tmp_path / "truth.csv"
    cfg = dataclasses.replace(mock_config(app_port, faults=FaultConfig(estimator_reset_at_s=3.0, estimator_reset_ned_m=(0.0, 0.0, -1.6))),
                              truth_log=str(truth_log))  # fmt: skip
    with run_in_thread(cfg) as mock:
        outcome, printed = fly_udpin(app_port, config, tmp_path / "log", "--airborne", "--duration", "8")
        mode, armed, _, events = _end(mock)
    truth = read_truth(truth_log)
    lowest = float(-truth.position_ned_m[:, 2].max())
    print(f"\n1.6 m vertical reset: exit {outcome.exit_code}, {outcome.reason}; lowest true altitude {lowest:.2f} m (floor {fence.floor_m:g} m)")
    assert outcome.exit_code == 5, printed
    assert "estimator reset moved the position estimate 1.60 m (vertical +1.60 m" in outcome.reason
    assert "AUTO.LOITER requested, confirmed" in outcome.reason and (mode, armed) == ("AUTO.LOITER", True)
    assert lowest > fence.floor_m
