"""limits.max_tangential_accel_m_s2: the speed loop's correction is bounded, so a vehicle at rest on
the path starts along it gently (on a real ArduCopter SITL the unbounded start tripped the tilt
watchdog on figure8.yaml; docs/controller.md, *Starting along the path*)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from pf_offboard.config import ConfigError, load_config, parse_config
from pf_offboard.control import PathFollower
from pf_offboard.control.law import ControlLaw
from pf_offboard.control.types import GRAVITY_M_S2, Gains, Limits
from pf_offboard.errors import InputError
from pf_offboard.sim.flight import SimSpec, simulate

ROOT = Path(__file__).resolve().parents[2]
FIGURE8 = ROOT / "configs" / "figure8.yaml"


def _tilt_deg(accel_enu_m_s2) -> float:
    a = np.asarray(accel_enu_m_s2, dtype=float)
    return math.degrees(math.atan2(math.hypot(a[0], a[1]), a[2] + GRAVITY_M_S2))


def test_the_bound_caps_the_correction_in_both_directions_and_leaves_small_errors_alone():
    law = ControlLaw(Gains(), Limits())  # default bound 1.5 m/s^2
    assert law.tangential(1.5, 0.0) == 1.5  # at rest, eta2_ref 1.5 m/s: shaped 7.7, bounded
    assert law.tangential(-1.5, 0.0) == -1.5
    assert law.tangential(0.0, 3.5) == -1.5  # thrown along the path: braking bounded too
    # the linear neighbourhood is the paper's law
    assert law.tangential(1.5, 1.499) == pytest.approx(law.kd_t * 0.001, rel=1e-12)
    unbounded = ControlLaw(Gains(), Limits(max_tangential_accel_m_s2=None))
    assert unbounded.tangential(1.5, 0.0) == pytest.approx(math.sqrt(2.0 * unbounded.jerk * (1.5 - 0.5 * unbounded.dv_lin_t)))
    assert unbounded.tangential(1.5, 0.0) > 7.0


def test_validation_and_config_field():
    for bad in (0.0, 0.05, 101.0, math.nan):
        with pytest.raises(InputError, match="max_tangential_accel_m_s2"):
            Limits(max_tangential_accel_m_s2=bad)
    path = {"waypoints": [[0, 0, 1], [1, 0, 1], [2, 1, 1], [3, 1, 1]]}
    assert parse_config({"path": path}).limits.max_tangential_accel_m_s2 == 1.5
    assert parse_config({"path": path, "limits": {"max_tangential_accel_m_s2": None}}).limits.max_tangential_accel_m_s2 is None
    assert parse_config({"path": path, "limits": {"max_tangential_accel_m_s2": 2.5}}).limits.max_tangential_accel_m_s2 == 2.5
    with pytest.raises(ConfigError) as err:
        parse_config({"path": path, "limits": {"max_tangential_accel_m_s2": 0.0}})
    assert err.value.field == "limits.max_tangential_accel_m_s2" and ">= 0.1" in err.value.reason


def test_paper_configs_keep_the_papers_unbounded_law():
    for name in ("paper.yaml", "speed-profile.yaml", "px4-sih.yaml"):
        assert load_config(ROOT / "configs" / name).limits.max_tangential_accel_m_s2 is None, name
    for name in ("figure8.yaml", "helix.yaml", "straight.yaml", "racetrack.yaml", "arducopter.yaml"):
        assert load_config(ROOT / "configs" / name).limits.max_tangential_accel_m_s2 == 1.5, name


def test_at_rest_on_the_path_the_first_command_is_gentle_and_reported_as_tangential_saturation():
    """figure8.yaml's crossing, hovering on the path: the command leans 1.5 m/s^2 along it (8.7 deg),
    not the shaped loop's 7.7 m/s^2 (38 deg); the speed integral is frozen meanwhile."""
    for bound, expected_tilt_deg in ((1.5, math.degrees(math.atan(1.5 / GRAVITY_M_S2))), (None, 38.0)):
        config = load_config(FIGURE8)
        base = PathFollower.from_config(config)
        f = PathFollower(base.path, config.speed_m_s, gains=config.gains,
                         limits=Limits(**{**config.limits.__dict__, "max_tangential_accel_m_s2": bound}))  # fmt: skip
        y = base.path.eval(0.0).sigma
        c = f.update(y, np.zeros(3))
        assert _tilt_deg(c.acceleration) == pytest.approx(expected_tilt_deg, abs=0.5), bound
        assert c.saturation.tangential == (bound is not None)
        t = base.path.frame(0.0).t
        assert float(np.dot(c.acceleration, t)) * np.sign(config.speed_m_s) > 0.0  # along the way to go


@pytest.mark.parametrize("output", ["attitude", "rates"])
def test_figure8_from_rest_on_the_arducopter_mock_leans_gently_and_converges(tmp_path, output):
    """Closed loop (mock ArduCopter, the shipped figure8.yaml, hover at its crossing): the commanded
    tilt stays under 30 deg (unbounded: 50 deg, the limit) and the flight settles on the path."""
    spec = SimSpec(vehicle="arducopter", autopilot="ardupilot", output_mode=output, laps=1.0, seed=1)
    res = simulate(FIGURE8, spec, tmp_path, write_logs=True)
    assert not res.crashed and res.activation_time_s is not None
    recs = [r for r in res.records if r.mode == "following"]
    t0 = recs[0].time_s
    first = [r for r in recs if r.time_s < t0 + 3.0]
    assert max(_tilt_deg(r.accel_cmd_enu_m_s2) for r in first) < 30.0
    late = [r for r in recs if r.time_s > t0 + 5.0]
    assert late and max(r.cross_track_m for r in late) < 0.05
    assert abs(np.mean([r.eta2_m_s - r.speed_ref_m_s for r in late])) < 0.05
