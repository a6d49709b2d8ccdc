"""Issue 24: the autopilot's own tilt limit. PX4 clips an acceleration setpoint's tilt at
MPC_TILTMAX_AIR (ControlMath::limitTilt); the mock does too. ``sim`` reads the parameter as
``fly`` does and plans (speed profile) and flies (law limits) within min(limits.max_tilt_deg, it).

Figure-eight tilted 20 deg, up to 3 m/s, px4-sih, acceleration output, seed 1, three laps, from
activation + 8 s: planned for 45 deg into a 30 deg clip the cross-track RMS was 36 cm (max 76);
planned for 30 deg, 4.6 cm (max 10), at a lower planned speed (lap 7.7 s against 6.4).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import yaml

from pf_offboard.control.profile import response_share
from pf_offboard.sim import SimSpec
from pf_offboard.sim.flight import SimFlight

from .helpers import errors, late_records

ROOT = Path(__file__).resolve().parents[2]
FIGURE8 = ROOT / "tests" / "real_sitl" / "configs" / "figure8-tilted.yaml"


def _config(tmp: Path) -> Path:
    data = yaml.safe_load(FIGURE8.read_text())
    data["speed_profile"] = {"max_speed_m_s": 3.0}
    path = tmp / "figure8-3.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def _fly(tmp: Path, name: str, params: tuple[tuple[str, float], ...], plan_for_the_clip: bool = True) -> tuple:
    spec = SimSpec(autopilot="px4", vehicle="px4-sih", output_mode="acceleration", laps=3.0, seed=1, name=name, autopilot_params=params)
    flight = SimFlight(_config(tmp), spec, tmp / name)
    if not plan_for_the_clip:  # the app as it was: the autopilot's limit not read
        flight.pipeline.follower.cap_tilt = lambda deg: None
    result = flight.run()
    ct, err = errors(late_records(result.records))
    return flight.pipeline.follower, ct, err, result


def _rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(x**2)))


@pytest.mark.integration
def test_sim_plans_within_mpc_tiltmax_air_and_tracks_better_than_planning_into_the_clip(tmp_path: Path) -> None:
    follower45, ct45, err45, _ = _fly(tmp_path, "t45", ())
    follower30, ct30, err30, r30 = _fly(tmp_path, "t30", (("MPC_TILTMAX_AIR", 30.0),))
    clipped, ct_clip, err_clip, _ = _fly(tmp_path, "t30-clip", (("MPC_TILTMAX_AIR", 30.0),), plan_for_the_clip=False)
    print(f"\nplanned max tilt 45: {follower45.profile.stats.max_tilt_deg:.1f} deg, 30: {follower30.profile.stats.max_tilt_deg:.1f} deg; "
          f"cross-track RMS / max: 45 {100 * _rms(ct45):.1f} / {100 * np.abs(ct45).max():.1f} cm, 30 {100 * _rms(ct30):.1f} / "
          f"{100 * np.abs(ct30).max():.1f} cm, 45 into a 30 clip {100 * _rms(ct_clip):.1f} / {100 * np.abs(ct_clip).max():.1f} cm; "
          f"speed error RMS {100 * _rms(err45):.1f} / {100 * _rms(err30):.1f} / {100 * _rms(err_clip):.1f} cm/s")  # fmt: skip
    assert r30.reason == "3 laps done"
    assert json.loads((r30.paths.tlog.parent / "summary.json").read_text())["tilt_limit_deg"] == 30.0
    assert follower45.limits.max_tilt_deg == 45.0 and clipped.limits.max_tilt_deg == 45.0
    assert follower30.limits.max_tilt_deg == 30.0 and follower30.law.limits.max_tilt_deg == 30.0
    # the plan uses at most its share of the 30 deg thrust set (g e_z + a_ref / share within 30 deg),
    # the rest kept for the feedback; its reference thrust tilts well inside 30 deg
    stats30 = follower30.profile.stats
    share = response_share(follower30.profile.spec.accel_share, follower30.profile.response_s)
    assert stats30.max_accel_use <= share + 1e-3
    assert stats30.max_tilt_deg < 20.0 < 25.0 < follower45.profile.stats.max_tilt_deg < 30.0  # for 45: ~2 deg left for the feedback
    # planning for the clip tracks far better than planning for 45 into it
    assert _rms(ct30) < 0.08 and np.abs(ct30).max() < 0.15
    assert _rms(ct_clip) > 3.0 * _rms(ct30) and np.abs(ct_clip).max() > 3.0 * np.abs(ct30).max()
    assert _rms(err30) < _rms(err_clip)


def test_sim_reads_ardupilots_lean_angle_limit(tmp_path: Path) -> None:
    """ArduPilot (AC_PosControl): PSC_ANGLE_MAX unless 0, then ANGLE_MAX (the arducopter preset's
    30 deg); acceleration output only (attitude targets are not clipped)."""
    config = _config(tmp_path)
    for params, output, expected in (((), "acceleration", 30.0), ((("PSC_ANGLE_MAX", 25.0),), "acceleration", 25.0),
                                     ((), "attitude", 45.0)):  # fmt: skip
        spec = SimSpec(autopilot="ardupilot", vehicle="arducopter", output_mode=output, duration_s=0.5, seed=1,
                       name=f"ap-{output}-{expected:g}", autopilot_params=params)  # fmt: skip
        flight = SimFlight(config, spec, tmp_path / spec.name, write_logs=False)
        flight.run()
        assert flight.pipeline.follower.limits.max_tilt_deg == expected, (params, output)
