"""A vehicle model with a faster vertical group, as ``identify`` writes it for PX4, on the mock.

``identify`` fits the horizontal and vertical groups' dead times separately; on PX4 SIH the
vertical one (thrust) is 0.00-0.04 s against 0.10-0.15 s for the horizontal (tilt). The
compensator predicts the whole state over the longer delay and sends the vertical setpoints that
much later, so the law sees the state at one instant. This flies ``px4-sih.yaml`` with such a
vertical group (delay 0.03 s, lag 0.04 s) on the calibrated ``px4-sih`` preset, `acceleration`
output, two laps from activation + 8 s as issue 8 measures, against the same config without it.

Measured (seed 1): 2.4 cm, 4.4 cm/s against 2.2 cm, 3.3 cm/s with one delay (the hand-set section
before: 2.5 cm, 4.6 cm/s against 2.3 cm, 3.8 cm/s). Predicting each
group over its own delay, as the compensator did before, flew the same model at 8.1 cm, 11.0 cm/s
(the real PX4 SIH, five laps: 8.1 cm, 11.4 cm/s; now 4.3 cm, 5.9 cm/s; docs/identify.md).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from pf_offboard.sim import SimSpec

from .helpers import errors, fly_px4_sih


def _fly(tmp: Path, name: str, vehicle: dict[str, float]) -> tuple[float, float, float]:
    """(cross-track RMS m, speed error RMS m/s, mean speed error m/s) from activation + 8 s."""
    spec = SimSpec(autopilot="px4", vehicle="px4-sih", output_mode="acceleration", laps=2.0, seed=1, name="flight")

    def edit(data: dict[str, Any]) -> None:
        data["vehicle"].update(vehicle)

    ct, err = errors(fly_px4_sih(tmp, name, edit, spec))
    return math.sqrt(float(np.mean(ct**2))), math.sqrt(float(np.mean(err**2))), float(np.mean(err))


@pytest.mark.integration
def test_a_faster_vertical_group_stays_close_to_one_delay(tmp_path: Path) -> None:
    ct, rms, mean = _fly(tmp_path, "two-delays", {"accel_delay_z_s": 0.03, "accel_lag_z_s": 0.04})
    ct_one, rms_one, _ = _fly(tmp_path, "one-delay", {})
    print(f"\npx4-sih acceleration: vertical delay 0.03 s {100 * ct:.1f} cm, {100 * rms:.1f} cm/s (mean {100 * mean:+.1f}); "
          f"one delay {100 * ct_one:.1f} cm, {100 * rms_one:.1f} cm/s")
    assert rms < 0.06 and abs(mean) < 0.02 and ct < 0.04
    assert rms < 1.5 * rms_one and ct < 1.5 * ct_one  # the vertical group acting early flies better still
