"""Flight summary: convergence figures, and whole-flight figures that never say only "n/a"."""

from __future__ import annotations

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
    """A real vehicle hovering on GPS: cross-track 8-20 cm, never within 5 cm: the convergence
    figures are n/a, the whole-flight ones are printed."""
    rng = np.random.default_rng(0)
    ct = rng.uniform(0.08, 0.2, 500)
    speed_err = rng.normal(-0.1, 0.2, 500)
    recs = [record(0.0, 0.5, 0.0, active=False)] + [record(0.02 * (k + 1), ct[k], -1.5 + speed_err[k]) for k in range(500)]
    s = summarize(recs)
    assert s.convergence_time_s is None and s.cross_track_rms_m is None
    assert s.whole_cross_track_rms_m == pytest.approx(math.sqrt(np.mean(ct**2)))
    assert s.whole_cross_track_max_m == pytest.approx(ct.max())
    assert s.whole_speed_error_rms_m_s == pytest.approx(math.sqrt(np.mean(speed_err**2)))
    assert s.whole_speed_error_mean_m_s == pytest.approx(np.mean(speed_err))
    whole = [line for line in s.lines() if line.startswith("whole flight")]
    assert len(whole) == 1 and "n/a" not in whole[0]
    assert f"{s.whole_cross_track_rms_m:.4f} m" in whole[0] and f"{s.whole_speed_error_mean_m_s:+.4f} m/s" in whole[0]


def test_whole_flight_includes_the_approach() -> None:
    recs = [record(0.1 * k, 1.0 if k < 10 else 0.01, -1.5) for k in range(100)]
    s = summarize(recs)
    assert s.cross_track_rms_m == pytest.approx(0.01)  # after convergence
    assert s.whole_cross_track_rms_m == pytest.approx(math.sqrt((10 * 1.0 + 90 * 1e-4) / 100))
    assert s.whole_cross_track_max_m == 1.0


def test_no_active_steps_whole_flight_is_na() -> None:
    s = summarize([record(0.0, 0.3, 0.0, active=False), record(0.1, 0.3, 0.0, active=False)])
    assert s.whole_cross_track_rms_m is None
    assert any(line.startswith("whole flight") and "n/a" in line for line in s.lines())
