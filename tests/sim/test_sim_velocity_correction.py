"""The velocity correction on the calibrated `px4-sih` preset, in closed loop through ``sim``.

The preset's estimator reports a velocity with EKF2's bias on PX4 SIH (0.20 / 0.10 m/s
Gauss-Markov over 4 s, not in the position; sitl_mock/dynamics/estimator.py), as measured against
SIH's ground truth. The shipped `configs/px4-sih.yaml` (acceleration output, velocity correction
0.3 s) on the paper path at 1.5 m/s, 3 laps, measured from activation + 8 s as on the real SITL:
once as shipped, once with `flight.velocity_correction_s: null`, once with the earlier 0.5 s.

Measured (seed 1, 3 laps): corrected 2.3 cm cross-track RMS, 0.5 s 2.9 cm, uncorrected
11.2 cm. The real PX4 SIH: 0.3 s 3.5-4.2 cm in every output mode, 0.5 s 3.9-5.3 cm,
uncorrected 10.9-17.7 cm.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from pf_offboard.sim import SimSpec

from .helpers import errors, fly_px4_sih


def _fly(tmp: Path, corrected: bool, time_constant_s: float | None = None) -> float:
    def edit(data: dict[str, Any]) -> None:
        assert data["flight"].get("velocity_correction_s", "auto") == "auto"  # as shipped (the default: PX4's 0.1 s)
        if not corrected:
            data["flight"]["velocity_correction_s"] = None
        elif time_constant_s is not None:
            data["flight"]["velocity_correction_s"] = time_constant_s

    name = ("corrected" if time_constant_s is None else f"corrected-{time_constant_s:g}") if corrected else "reported"
    spec = SimSpec(autopilot="px4", vehicle="px4-sih", laps=3.0, seed=1, name="flight")
    ct, _ = errors(fly_px4_sih(tmp, name, edit, spec))
    return math.sqrt(float(np.mean(np.square(ct))))


@pytest.fixture(scope="module")
def shipped(tmp_path_factory: pytest.TempPathFactory) -> float:
    """The flight as shipped, which both tests compare with: flown once (seeded, deterministic)."""
    return _fly(tmp_path_factory.mktemp("shipped"), True)


@pytest.mark.integration
def test_velocity_correction_removes_the_ekf_velocity_bias_in_closed_loop(tmp_path: Path, shipped: float) -> None:
    corrected, reported = shipped, _fly(tmp_path, False)
    print(f"\npx4-sih, px4-sih.yaml: corrected {100 * corrected:.1f} cm RMS, velocity as reported {100 * reported:.1f} cm")
    assert corrected < 0.05  # issue 8's target
    assert corrected < 0.5 * reported


@pytest.mark.integration
def test_shipped_time_constant_flies_closer_than_the_earlier_one(tmp_path: Path, shipped: float) -> None:
    """0.3 s takes the position's content up to about 0.5 Hz, where EKF2's position is the better
    of the two (docs/app.md, velocity consistency); 0.5 s flew further off the path, on the mock
    as on the real PX4 SIH, at the same speed error."""
    earlier = _fly(tmp_path, True, 0.5)
    print(f"\npx4-sih, px4-sih.yaml: velocity correction 0.3 s {100 * shipped:.2f} cm RMS, 0.5 s {100 * earlier:.2f} cm")
    assert shipped < 0.9 * earlier
