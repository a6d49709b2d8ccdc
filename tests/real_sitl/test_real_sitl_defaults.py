"""The default config on a held-out path, the paper's thrown start on a real autopilot, and its
closest kin on PX4 (opt-in, real SITL; the flights are scripts/real_sitl_campaign.py's).

- The default config (a path and a speed): the tilted figure-eight of ``configs/`` at 1.5 m/s, three
  laps, every output mode, judged from activation + 8 s with the speed along the path from the
  position's derivative against the issue's targets (ArduCopter <= 2 cm / 3 cm/s, PX4 SIH <= 4 cm /
  5 cm/s).

Skipped unless PF_OFFBOARD_ARDUCOPTER / PF_OFFBOARD_PX4_SITL point at SITL builds (see
test_real_sitl.py). Run each in its own network namespace (``unshare -n``): the SITLs use fixed ports.

- ArduCopter SITL: ``pf-offboard fly --throw 1.8`` waits; a ground station on the second MAVLink
  port arms the vehicle in THROW mode (THROW_MOT_START 1: motors idling) and shoves it (SIM_SHOVE_*: up and sideways, ~4 m/s); its
  motors start; the app takes over when it crosses 1.8 m and follows the held-out racetrack.
- PX4 SIH (no throw in SIH): a ground station takes off and sends the vehicle away at cruise speed
  (a reposition); ``fly --airborne`` engages it metres off the path, moving fast away from it.

Each must activate, converge (the summary's rule: within 10 cm for 1 s) within 3 s of activation
and follow (exit 0 after 10 s, never more than 25 cm off after converging). Figures: scripts/
real_sitl_campaign.py --starts.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from types import ModuleType

import pytest

from pf_offboard.config import load_config
from pf_offboard.logs import measures
from pf_offboard.logs.steplog import read_steplog

pytestmark = pytest.mark.real_sitl

CONFIGS = Path(__file__).resolve().parent / "configs"


def _judge(result: dict, config: Path) -> tuple[float, float, float]:
    """(convergence s after activation, cross-track max after it m, speed at activation m/s)."""
    assert result.get("exit_code") == 0, result.get("stderr")
    recs = read_steplog(Path(result["spec"]["workdir"]) / "log" / "flight.csv")
    active = [r for r in recs if r.active]
    assert active, "never activated"
    track = measures.tracking_of_records(recs, measures.path_tangent(load_config(config).path.spline()))
    assert track is not None and track.convergence_time_s is not None, "never converged"
    t_conv = active[0].time_s + track.convergence_time_s
    after = max(r.cross_track_m for r in active if r.time_s >= t_conv)
    speed = sum(v * v for v in active[0].velocity_enu_m_s) ** 0.5
    print(f"\nactivated {active[0].cross_track_m:.2f} m off at {speed:.2f} m/s; converged after {track.convergence_time_s:.2f} s; "
          f"then at most {100 * after:.1f} cm off")  # fmt: skip
    return track.convergence_time_s, after, speed


@pytest.mark.skipif(os.environ.get("PF_OFFBOARD_ARDUCOPTER") is None, reason="set PF_OFFBOARD_ARDUCOPTER to fly ArduCopter SITL")
def test_arducopter_thrown_start(tmp_path: Path, script) -> None:
    c = script("real_sitl_campaign")
    config = CONFIGS / "racetrack.yaml"
    result = c.run_one(c.throw_spec(c.THROWS[3], tmp_path / "throw", config))
    conv, after, speed = _judge(result, config)
    assert speed > 1.0  # it was thrown, not lifted
    assert conv <= 3.0 and after <= 0.25


@pytest.mark.skipif(os.environ.get("PF_OFFBOARD_PX4_SITL") is None, reason="set PF_OFFBOARD_PX4_SITL to fly the real PX4 SIH")
def test_px4_fast_off_path_start(tmp_path: Path, script) -> None:
    c = script("real_sitl_campaign")
    config = CONFIGS / "racetrack.yaml"
    # the fastest of the campaign's starts: sent away at 3 m/s, engaged at 1.98-2.27 m/s (the 2 m/s one
    # is engaged at 1.69-1.76 m/s); the bound checks the start was that one, not the follower
    result = c.run_one(c.fast_start_spec(c.FAST_STARTS[2], tmp_path / "fast", config))
    conv, after, speed = _judge(result, config)
    assert speed > 1.85
    assert conv <= 3.0 and after <= 0.25


# ------------------------------------------------------------------ the default config, held-out paths
@pytest.mark.skipif(os.environ.get("PF_OFFBOARD_ARDUCOPTER") is None, reason="set PF_OFFBOARD_ARDUCOPTER to fly ArduCopter SITL")
@pytest.mark.parametrize("output", ["attitude", "rates"])
def test_arducopter_default_config_on_a_held_out_path(tmp_path: Path, output: str, script) -> None:
    """A path and a speed (1.5 m/s), nothing else, on the tilted figure-eight nobody tuned on:
    <= 2 cm cross-track RMS and <= 3 cm/s speed error RMS from the position's derivative, from
    activation + 8 s over three laps."""
    settled = _default_flight(script("real_sitl_campaign"), tmp_path, "arducopter", output)
    assert settled["cross_track_rms_m"] <= 0.02 and settled["speed_error_rms_m_s"] <= 0.03
    if output == "attitude":  # ArduCopter answers attitude targets sooner than the typical model says:
        # the identification adopts a shorter dead time (0.04 s in 3 of 3 flights, 2026-11-28;
        # without it this flight is 2.3-2.5 cm, 6.3-6.6 cm/s)
        summary = json.loads((tmp_path / "flight" / "log" / "summary.json").read_text(encoding="utf-8"))["summary"]
        model = summary["identified_model"]
        assert model is not None and model["delay_s"] < 0.1


@pytest.mark.skipif(os.environ.get("PF_OFFBOARD_PX4_SITL") is None, reason="set PF_OFFBOARD_PX4_SITL to fly the real PX4 SIH")
@pytest.mark.parametrize("output", ["acceleration", "attitude", "rates"])
def test_px4_default_config_on_a_held_out_path(tmp_path: Path, output: str, script) -> None:
    """As above on PX4 SIH: <= 4 cm and <= 5 cm/s (on the estimate, which the app steers; the
    printed ground-truth figures show where EKF2's own error puts the vehicle)."""
    settled = _default_flight(script("real_sitl_campaign"), tmp_path, "px4", output)
    assert settled["cross_track_rms_m"] <= 0.04 and settled["speed_error_rms_m_s"] <= 0.05


def _default_flight(c: ModuleType, tmp_path: Path, autopilot: str, output: str) -> dict:
    """``c``: scripts/real_sitl_campaign.py, whose run_one flies it."""
    spec = {"autopilot": autopilot, "config": str(CONFIGS / "figure8-tilted.yaml"), "output": output, "laps": 3,
            "workdir": str(tmp_path / "flight")}  # fmt: skip
    result = c.run_one(spec)
    print("\n" + c.row(result))
    assert result.get("exit_code") == 0, result.get("stderr")
    settled = result["tracking"]["settled"]
    assert settled is not None
    return settled
