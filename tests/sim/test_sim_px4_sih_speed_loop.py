"""The shipped `px4-sih.yaml`'s speed loop on the calibrated `px4-sih` preset, through ``sim``.

EKF2's estimate error on SIH reaches the speed loop at 0.3-2 Hz, where the loop (a Smith predictor
cannot take the inner loop's delay out of the noise path) amplifies it, and the disturbance
observer passes it into the command below its bandwidth. The shipped config runs the observer at
1 rad/s and gives the speed loop a 30° margin (2.65 Hz); before, 4 rad/s (2026-11-21 to -25) and
8 rad/s with 40° (1.47 Hz) passed more of the noise on. `rates` output, two laps from activation
+ 8 s as issue 8 measures.

Measured (seed 1, velocity correction 0.3 s): shipped 3.14 cm/s at 2.25 cm; observer 4 rad/s 3.62 at 2.30; observer
8 rad/s and 40° 4.50 at 2.33. With the 0.1 s default correction every variant passes less of the estimate's
error on (the law damps with its position's velocity): 2.74 at 1.73, 2.77 at 1.63, 3.09 at 1.35. On
the real PX4 SIH the observer at 1 rad/s flew less speed error than at 4 in every output mode, over
five laps (3.84-3.85 cm/s against 4.17-4.30) and over two laps at every start time tried
(docs/controller.md, *A slower observer*).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import yaml

from pf_offboard.sim import SimSpec

from .helpers import PX4_SIH, errors, fly_px4_sih


def _fly(tmp: Path, name: str, compensation: dict[str, float]) -> tuple[float, float, float]:
    """(cross-track RMS m, speed error RMS m/s, mean speed error m/s) from activation + 8 s."""
    spec = SimSpec(autopilot="px4", vehicle="px4-sih", output_mode="rates", laps=2.0, seed=1, name="flight")
    ct, err = errors(fly_px4_sih(tmp, name, lambda data: data["compensation"].update(compensation), spec))
    return math.sqrt(float(np.mean(ct**2))), math.sqrt(float(np.mean(err**2))), float(np.mean(err))


@pytest.mark.integration
def test_shipped_speed_loop_meets_the_target_where_the_earlier_ones_did_not(tmp_path: Path) -> None:
    shipped_comp = yaml.safe_load(PX4_SIH.read_text())["compensation"]
    assert (shipped_comp["observer_rad_s"], shipped_comp["tangential_phase_margin_deg"]) == (1.0, 30.0)
    ct, rms, mean = _fly(tmp_path, "shipped", {})
    ct_prev, rms_prev, _ = _fly(tmp_path, "previous", {"observer_rad_s": 4.0})
    ct_old, rms_old, _ = _fly(tmp_path, "earlier", {"observer_rad_s": 8.0, "tangential_phase_margin_deg": 40.0})
    print(f"\npx4-sih rates: shipped {100 * ct:.2f} cm, {100 * rms:.2f} cm/s (mean {100 * mean:+.2f}); "
          f"observer 4 rad/s: {100 * ct_prev:.2f} cm, {100 * rms_prev:.2f} cm/s; "
          f"observer 8 rad/s, margin 40 deg: {100 * ct_old:.2f} cm, {100 * rms_old:.2f} cm/s")  # fmt: skip
    assert rms < 0.05 and abs(mean) < 0.02 and ct < 0.05  # issue 8's targets
    assert rms < rms_prev and ct < ct_prev + 0.002
    assert rms < 0.9 * rms_old
