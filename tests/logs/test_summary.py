"""Flight summary: one convergence rule, two named windows, the speed along the path from the position."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from pf_offboard.logs.steplog import StepRecord
from pf_offboard.logs.summary import summarize


def record(t: float, cross_track_m: float, eta2_m_s: float, active: bool = True, speed_ref_m_s: float = -1.5) -> StepRecord:
    nan3 = (math.nan, math.nan, math.nan)
    return StepRecord(
        time_s=t, mode="following" if active else "waiting", active=active, position_enu_m=np.zeros(3),
        velocity_enu_m_s=np.zeros(3), lam=0.0, eta1_m=0.0, eta2_m_s=eta2_m_s, xi1_m=cross_track_m, xi2_m_s=0.0,
        phi1_m=0.0, phi2_m_s=0.0, cross_track_m=cross_track_m, speed_ref_m_s=speed_ref_m_s,
        accel_cmd_enu_m_s2=np.array(nan3), thrust_cmd_m_s2=math.nan, q_cmd_enu_flu=np.array((1.0, 0, 0, 0)),
        rates_cmd_flu_rad_s=np.array(nan3), yaw_cmd_rad=0.0, yaw_rate_cmd_rad_s=0.0, sat_tangential=False,
        sat_transversal=False, sat_tilt=False, sat_thrust=False, sat_approach_speed=False, event="",
    )  # fmt: skip


def test_whole_flight_figures_when_convergence_never_holds() -> None:
    """A real vehicle hovering on GPS: cross-track 11-20 cm, never within 10 cm for 1 s: no
    convergence, but both windows' figures are printed, each naming its window."""
    rng = np.random.default_rng(0)
    ct = rng.uniform(0.11, 0.2, 500)
    speed_err = rng.normal(-0.1, 0.2, 500)
    recs = [record(0.0, 0.5, 0.0, active=False)] + [record(0.02 * (k + 1), ct[k], -1.5 + speed_err[k]) for k in range(500)]
    s = summarize(recs)
    assert s.convergence_time_s is None and s.whole is not None and s.settled is not None
    assert s.whole.cross_track_rms_m == pytest.approx(math.sqrt(np.mean(ct**2)))
    assert s.whole.cross_track_max_m == pytest.approx(ct.max())
    assert s.whole.estimator_speed_error_rms_m_s == pytest.approx(math.sqrt(np.mean(speed_err**2)))
    assert s.whole.estimator_speed_error_mean_m_s == pytest.approx(np.mean(speed_err))
    late = np.array([r.time_s >= 0.02 + 8.0 for r in recs[1:]])
    assert s.settled.cross_track_rms_m == pytest.approx(math.sqrt(np.mean(ct[late] ** 2)))
    assert s.whole.speed_error_rms_m_s is None  # no path given: no position-derived speed
    whole = [line for line in s.lines() if line.startswith("whole flight")]
    settled = [line for line in s.lines() if line.startswith("from activation + 8 s")]
    assert len(whole) == 1 and len(settled) == 1
    assert f"cross-track RMS {100 * s.whole.cross_track_rms_m:.2f} cm" in whole[0]
    assert f"mean {100 * s.whole.estimator_speed_error_mean_m_s:+.2f} cm/s" in whole[0]
    assert any(line.startswith("converged") and "never" not in line and "n/a" in line for line in s.lines())


def test_convergence_is_the_first_second_within_10_cm() -> None:
    """1 m off for 1 s, 8 cm for 0.5 s, 12 cm once, then 1 cm: converged where the 1 cm stretch
    begins (the 8 cm stretch is too short), and the windows include the approach or not."""
    cts = [1.0] * 10 + [0.08] * 5 + [0.12] + [0.01] * 104
    recs = [record(0.1 * k, c, -1.5) for k, c in enumerate(cts)]
    s = summarize(recs)
    assert s.convergence_time_s == pytest.approx(1.6)
    assert s.whole is not None and s.settled is not None
    assert s.whole.cross_track_rms_m == pytest.approx(math.sqrt(np.mean(np.square(cts))))
    assert s.whole.cross_track_max_m == 1.0
    assert s.settled.cross_track_rms_m == pytest.approx(0.01) and s.settled.start_s == 8.0
    assert s.settled.samples == sum(1 for k in range(len(cts)) if 0.1 * k >= 8.0 - 1e-12)


def test_speed_from_the_position_not_the_estimators_velocity() -> None:
    """The vehicle moves at 1.4 m/s along a straight path (+x) while the estimator says 1.5: the
    speed error from the position is -0.1 m/s, the estimator's 0 (reported beside it)."""
    recs = []
    for k in range(1200):  # 12 s at 100 Hz
        t = 0.01 * k
        r = record(t, 0.01, 1.5, speed_ref_m_s=1.5)
        recs.append(StepRecord(**{**r.__dict__, "position_enu_m": (1.4 * t, 0.0, 2.0)}))
    s = summarize(recs, tangent=lambda lam: np.array([1.0, 0.0, 0.0]))
    for w in (s.settled, s.whole):
        assert w is not None
        assert w.speed_mean_m_s == pytest.approx(1.4, abs=1e-9)
        assert w.speed_error_mean_m_s == pytest.approx(-0.1, abs=1e-9)
        assert w.speed_error_rms_m_s == pytest.approx(0.1, abs=1e-9)
        assert w.estimator_speed_error_rms_m_s == pytest.approx(0.0, abs=1e-12)
    # the first and last 0.1 s have no central difference: left out of the speed, kept for the rest
    assert s.whole is not None and s.whole.samples == 1200
    # flown backwards along the path (reference -1.4): the mean speed is along the direction of travel
    back = [StepRecord(**{**r.__dict__, "position_enu_m": (-r.position_enu_m[0], 0.0, 2.0), "speed_ref_m_s": -1.4}) for r in recs]
    w = summarize(back, tangent=lambda lam: np.array([1.0, 0.0, 0.0])).whole
    assert w is not None and w.speed_mean_m_s == pytest.approx(1.4) and w.speed_error_rms_m_s == pytest.approx(0.0, abs=1e-9)


def test_no_active_steps_windows_are_na() -> None:
    s = summarize([record(0.0, 0.3, 0.0, active=False), record(0.1, 0.3, 0.0, active=False)])
    assert s.whole is None and s.settled is None and s.whole_cross_track_rms_m is None
    assert any(line.startswith("whole flight") and "n/a" in line for line in s.lines())


class _Follower:
    """A closed path of 10 m with a lap-time bound (what the summary reads of a PathFollower)."""

    class path:  # noqa: N801
        closed = True
        length_m = 10.0

    @staticmethod
    def lap_time_bound_s() -> float:
        return 4.0


@pytest.mark.parametrize("direction", [1.0, -1.0])
def test_lap_times_from_the_net_progress(direction: float) -> None:
    """eta1 wraps at 10 m; travelling at 2 m/s (with jitter backwards) from eta1 = 3 m: laps of 5 s
    each, crossing times interpolated; the bound is printed beside them and in the JSON."""
    rng = np.random.default_rng(1)
    recs = []
    for k in range(1301):  # 13 s at 100 Hz: 26 m, two whole laps
        t = 0.01 * k
        e = (3.0 + direction * 2.0 * t + rng.uniform(-0.02, 0.02)) % 10.0
        recs.append(dataclasses.replace(record(t, 0.01, 2.0 * direction, speed_ref_m_s=2.0 * direction), eta1_m=e))
    s = summarize(recs, follower=_Follower())
    assert len(s.lap_times_s) == 2
    assert s.lap_times_s == pytest.approx((5.0, 5.0), abs=0.02)
    assert s.lap_time_bound_s == 4.0
    line = [x for x in s.lines() if x.startswith("lap times")][0]
    assert "5.00, 5.00 s" in line or "4.99" in line or "5.01" in line
    assert "bound at the vehicle's limits 4.00 s" in line
    d = s.to_dict()
    assert d["lap_time_bound_s"] == 4.0 and len(d["lap_times_s"]) == 2


def test_no_lap_times_without_a_closed_path() -> None:
    recs = [record(0.01 * k, 0.01, -1.5) for k in range(100)]
    s = summarize(recs)
    assert s.lap_times_s == () and s.lap_time_bound_s is None
    assert not any(x.startswith("lap times") for x in s.lines())


def test_the_last_identified_model_is_the_summarys() -> None:
    """``identified: ...`` events (the pipeline logs one per adoption of an inner-loop model, among
    other events of the step): the summary reports the last one and when; none: null."""
    from pf_offboard.logs.summary import identified_event, parse_identified

    first = identified_event(0.1, 0.04, 0.25)
    assert parse_identified(first) == {"lag_s": 0.1, "delay_s": 0.04, "drag_1_s": 0.25}
    assert parse_identified("identified: lag_s=x") is None and parse_identified("activated") is None
    joint = identified_event(0.1, 0.13, 0.85, gain_xy=0.9, gain_z=0.8, drag_z_1_s=0.7)  # a joint model's fit
    assert parse_identified(joint) == {"lag_s": 0.1, "delay_s": 0.13, "drag_1_s": 0.85, "gain_xy": 0.9, "gain_z": 0.8, "drag_z_1_s": 0.7}
    recs = [record(0.02 * k, 0.01, -1.5) for k in range(400)]
    plain = summarize(recs)
    assert plain.identified_model is None and plain.to_dict()["identified_model"] is None
    assert any(line.startswith("identified model") and "none adopted" in line for line in plain.lines())
    recs[150] = dataclasses.replace(recs[150], event=first)
    recs[250] = dataclasses.replace(recs[250], event="hold: x;" + identified_event(0.1, 0.0, 0.3125))
    s = summarize(recs)
    assert s.identified_model == {"lag_s": 0.1, "delay_s": 0.0, "drag_1_s": 0.3125, "adopted_at_s": recs[250].time_s}
    assert s.to_dict()["identified_model"] == s.identified_model
    line = next(x for x in s.lines() if x.startswith("identified model"))
    assert "dead time 0.000 s" in line and "drag 0.312 1/s" in line and f"t={recs[250].time_s:.3f} s" in line


def test_a_rolled_back_adoption_no_longer_counts() -> None:
    """``rolled_back: ...`` (the rollback guard undid the last adoption): the summary's model is the
    one adopted before it again, or none."""
    from pf_offboard.logs.summary import ROLLED_BACK_PREFIX, identified_event, rolled_back_event

    event = rolled_back_event(0.1, 0.25, 3.0, 0.5, 0.11, 0.024, 0.4, 0.06)
    assert event.startswith(ROLLED_BACK_PREFIX) and "gain_xy=0.5" in event and "cross_track_rms_m=0.11" in event
    recs = [record(0.02 * k, 0.01, -1.5) for k in range(400)]
    recs[100] = dataclasses.replace(recs[100], event=identified_event(0.1, 0.04, 0.25))
    recs[200] = dataclasses.replace(recs[200], event=identified_event(0.1, 0.25, 3.0, gain_xy=0.5))
    recs[300] = dataclasses.replace(recs[300], event=event)
    s = summarize(recs)
    assert s.identified_model == {"lag_s": 0.1, "delay_s": 0.04, "drag_1_s": 0.25, "adopted_at_s": recs[100].time_s}
    alone = summarize([dataclasses.replace(r, event="") if i == 100 else r for i, r in enumerate(recs)])
    assert alone.identified_model is None
