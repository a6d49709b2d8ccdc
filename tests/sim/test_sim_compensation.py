"""The inner-loop compensation on a realistic mock vehicle, in closed loop through ``sim``.

The `arducopter` preset (3 kg, ArduPilot's default attitude/rate tuning, the ArduPilot profile's
attitude-target handling) flown in `attitude` output on the paper path at 1.5 m/s: once with the
defaults of a config without gains/vehicle/compensation sections (gains: auto from the typical
vehicle model, compensation on), once with the uncompensated paper law at the hand-tuned 1.5 Hz
gains that were the best users had (issue 8). Measured from activation + 8 s, as on the real SITLs.

Measured (seed 0): compensated 2.0 cm cross-track RMS, mean speed error +0.1 cm/s; uncompensated
20.4 cm and +9.4 cm/s. On the real ArduCopter SITL the compensated defaults reach 2.8 cm
(attitude) and 3.6 cm (rates); the preset is calibrated on those closed-loop figures
(sitl_mock/dynamics/params.py, ARDUCOPTER_ROLL_AUTHORITY_CALIBRATION).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
import yaml

from pf_offboard.sim import SimSpec, simulate

from .helpers import errors, late_records

ROOT = Path(__file__).resolve().parents[2]
PAPER = ROOT / "configs" / "paper.yaml"


def _config(tmp: Path, compensated: bool, output_mode: str = "attitude") -> Path:
    data = yaml.safe_load(PAPER.read_text())
    for key in ("gains", "vehicle", "compensation"):
        data.pop(key, None)  # the defaults: gains auto, typical vehicle, compensation on
    if not compensated:
        data["compensation"] = {"enabled": False}
        data["gains"] = {"transversal": {"bandwidth_hz": 1.5, "damping": 1.0}, "tangential": {"bandwidth_hz": 1.0, "damping": 0.8}}
    data["flight"]["output_mode"] = output_mode
    path = tmp / (f"comp-{output_mode}.yaml" if compensated else "base.yaml")
    path.write_text(yaml.safe_dump(data))
    return path


def _flown(tmp: Path, compensated: bool, output_mode: str = "attitude") -> tuple[np.ndarray, np.ndarray]:
    """Cross-track (m) and speed error (m/s) samples from activation + 8 s."""
    spec = SimSpec(autopilot="ardupilot", vehicle="arducopter", laps=2.0, seed=0, name="flight")
    res = simulate(_config(tmp, compensated, output_mode), spec, tmp / (f"comp-{output_mode}" if compensated else "base"))
    return errors(late_records(res.records))


@pytest.fixture(scope="module")
def flown(tmp_path_factory: pytest.TempPathFactory) -> Callable[..., tuple[np.ndarray, np.ndarray]]:
    """``_flown`` once per (compensated, output mode) in this module: the compensated attitude
    flight is both tests' (seeded, deterministic)."""
    done: dict[tuple[bool, str], tuple[np.ndarray, np.ndarray]] = {}

    def get(compensated: bool, output_mode: str = "attitude") -> tuple[np.ndarray, np.ndarray]:
        if (compensated, output_mode) not in done:
            done[compensated, output_mode] = _flown(tmp_path_factory.mktemp("flight"), compensated, output_mode)
        return done[compensated, output_mode]

    return get


def _fly(flown: Callable[..., tuple[np.ndarray, np.ndarray]], compensated: bool) -> tuple[float, float]:
    ct, err = flown(compensated)
    return math.sqrt(float(np.mean(ct**2))), float(np.mean(err))


@pytest.mark.integration
def test_compensation_beats_the_uncompensated_law_on_a_realistic_vehicle(flown) -> None:
    ct_c, mean_c = _fly(flown, True)
    ct_b, mean_b = _fly(flown, False)
    print(f"\ncompensated: {100 * ct_c:.1f} cm RMS, mean speed error {100 * mean_c:+.1f} cm/s; "
          f"uncompensated 1.5 Hz: {100 * ct_b:.1f} cm, {100 * mean_b:+.1f} cm/s")  # fmt: skip
    assert ct_c < 0.05  # the real SITL: 2.8 cm
    assert ct_c < 0.3 * ct_b
    assert abs(mean_c) < 0.02
    assert abs(mean_c) < 0.03 < abs(mean_b)


@pytest.mark.integration
@pytest.mark.parametrize("output_mode", ["attitude", "rates"])
def test_one_lead_not_two_in_attitude_and_rates_output(flown, output_mode: str) -> None:
    """ArduPilot honours roll/pitch rate feed-forward next to an attitude target, and in rates
    output the app's own attitude loop adds it: with the compensator's lag lead in the setpoint as
    well, the path was led twice (seed 0: 2.1 cm, 3.3 cm/s in attitude, 1.9 cm, 2.8 cm/s in rates).
    With the lead alone (the command's body rates carry the yaw rate only) the same flights are
    within 1 cm and 1.5 cm/s (measured 0.7 cm, 0.9 / 0.8 cm/s; the real ArduCopter SITL, velocity
    correction 0.5 s, went from 2.0 cm, 2.1 cm/s to 1.6 cm, 1.1 cm/s in attitude and from 2.7 cm,
    2.9 cm/s to 1.4 cm, 1.1 cm/s in rates)."""
    ct, err = flown(True, output_mode)
    ct_rms, err_rms = math.sqrt(float(np.mean(ct**2))), math.sqrt(float(np.mean(err**2)))
    print(f"\n{output_mode}: {100 * ct_rms:.2f} cm RMS, speed error {100 * err_rms:.2f} cm/s RMS")
    assert ct_rms < 0.01
    assert err_rms < 0.015
