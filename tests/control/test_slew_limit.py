"""The slew limit (limits.max_tilt_rate_rad_s): config field, validation, and the shape of the law
(linear near the path, square-root beyond, continuous, bounded rate of change of the demand)."""

from __future__ import annotations

import math

import numpy as np
import pytest
import yaml
from conftest import PAPER_YAML

from pf_offboard.control.types import Compensation, Gains
from pf_offboard import Gains, Limits, PathFollower
from pf_offboard.config import ConfigError, load_config, parse_config
from pf_offboard.control.law import ControlLaw
from pf_offboard.control.types import GRAVITY_M_S2
from pf_offboard.errors import InputError


def _minimal(**limits):
    data = yaml.safe_load(PAPER_YAML.read_text())
    data["limits"] = limits
    return data


def test_default_and_config_round_trip():
    assert Limits().max_tilt_rate_rad_s == 2.0
    assert load_config(PAPER_YAML).limits.max_tilt_rate_rad_s == 2.0  # paper.yaml does not set it
    assert parse_config(_minimal(max_tilt_rate_rad_s=3.5)).limits.max_tilt_rate_rad_s == 3.5
    assert parse_config(_minimal(max_tilt_rate_rad_s=None)).limits.max_tilt_rate_rad_s is None


@pytest.mark.parametrize("value,reason", [(0.0, ">= 0.1"), (150.0, "<= 100"), ("fast", "number"), (True, "number")])
def test_config_rejects_bad_values(value, reason):
    with pytest.raises(ConfigError) as err:
        parse_config(_minimal(max_tilt_rate_rad_s=value))
    assert err.value.field == "limits.max_tilt_rate_rad_s"
    assert reason in err.value.reason


@pytest.mark.parametrize("value", [0.05, 101.0, math.nan, math.inf])
def test_limits_rejects_bad_values(value):
    with pytest.raises(InputError):
        Limits(max_tilt_rate_rad_s=value)


def test_velocity_loop_shape():
    """Linear (paper gain) up to J/kd^2, then sqrt(2 J (dv - dv_lin/2)): continuous with a continuous
    slope, monotonic, and |u| kd <= ~J along the way (the demand's rate of change in the linear loop)."""
    law = ControlLaw(Gains(), Limits())
    J = GRAVITY_M_S2 * 2.0
    kd = law.kd
    assert law.dv_lin == pytest.approx(J / kd**2)
    dv = np.linspace(0.0, 3.0, 30001)
    u = np.array([law.shape(kd, law.dv_lin, x) for x in dv])
    lin = dv <= law.dv_lin
    assert np.allclose(u[lin], kd * dv[lin])
    assert np.all(np.diff(u) > 0.0)
    # no kink at the junction: one-sided slopes agree
    x0, h = law.dv_lin, 1e-9
    left = (law.shape(kd, x0, x0) - law.shape(kd, x0, x0 - h)) / h
    right = (law.shape(kd, x0, x0 + h) - law.shape(kd, x0, x0)) / h
    assert left == pytest.approx(kd, rel=1e-5) and right == pytest.approx(kd, rel=1e-4)
    # time scale of the correction |dv|/|u| never shorter than the jerk-limited one sqrt(dv/2J)
    big = dv > law.dv_lin
    assert np.all(dv[big] / u[big] >= np.sqrt(dv[big] / (2 * J)) - 1e-12)


def test_none_is_the_paper_law():
    """Without the slew limit (and the tangential bound) the law is the paper's nested PD at any size."""
    limits = Limits(max_tilt_rate_rad_s=None, max_tilt_deg=80.0, max_thrust_m_s2=100.0, max_tangential_accel_m_s2=None)
    law = ControlLaw(Gains(), limits)
    kp, kd = law.kp, law.kd
    ux, uy, reduced, _ = law.transversal(0.001, 0.03, -0.0005, 0.0)
    assert not reduced
    assert ux == pytest.approx(-kp * 0.001 - kd * 0.03)
    assert uy == pytest.approx(kp * 0.0005)
    assert law.tangential(1.5, 1.0) == pytest.approx(law.kd_t * 0.5)


def test_approach_profile_continuous_and_slower_than_linear():
    law = ControlLaw(Gains(), Limits())
    d = np.geomspace(1e-6, 10.0, 4000)
    v = np.array([law.approach_speed(x)[0] for x in d])
    assert np.all(np.diff(v) >= 0.0)
    assert np.all(v <= law.k_pos * d + 1e-15)
    assert v[0] == pytest.approx(law.k_pos * d[0])  # linear at the path
    assert np.max(np.abs(np.diff(v))) < 0.01  # no jumps


def test_command_rate_of_change_bounded_near_the_path(paper_path):
    """The failure mode on a real vehicle: 0.2 m/s transversal velocity error near the path. Paper
    law: ~10 m/s^2 demand; shaped: a few m/s^2 and it changes along the ideal closed-loop motion
    at no more than a few J (checked on the double integrator at 1 ms)."""
    f = PathFollower(paper_path, speed=-1.5, gains=Gains.paper(), compensation=Compensation.off())
    lam = 0.3 * paper_path.lam_max
    fr = paper_path.frame(lam)
    y = paper_path.eval(lam).sigma + 0.002 * fr.e2
    v = -1.5 * fr.t + 0.2 * fr.e3
    J = GRAVITY_M_S2 * f.limits.max_tilt_rate_rad_s
    dt = 1e-3
    prev = None
    worst = 0.0
    for k in range(1500):
        c = f.update(y, v)
        a = c.acceleration
        if prev is not None:
            worst = max(worst, float(np.linalg.norm(a - prev)) / dt)
        prev = a
        v = v + dt * a
        y = y + dt * v
    st = c.state
    assert math.hypot(st.xi1, st.phi1) < 1e-3
    print(f"largest |da/dt| {worst:.1f} m/s^3 (J = {J:.1f})")
    assert worst < 4.0 * J
