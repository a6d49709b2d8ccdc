"""The shipped `px4-sih.yaml`'s speed loop on the calibrated `px4-sih` preset, through ``sim``.

EKF2's estimate error on SIH reaches the speed loop at 0.3-2 Hz, where the loop (a Smith predictor
cannot take the inner loop's delay out of the noise path) amplifies it. The shipped config runs
the disturbance observer at 4 rad/s and gives the speed loop a 30° margin (2.76 Hz); the earlier
8 rad/s and 40° (1.47 Hz) passed more of the noise on. `rates` output, the preset's hardest mode,
two laps from activation + 8 s as issue 8 measures.

Measured (seed 1): shipped 3.6 cm/s speed error RMS at 2.3 cm, earlier 4.4 cm/s at 2.3 cm (with the
hand-set vehicle section before the identified one: 4.2 cm/s at 2.5 cm against 5.8 at 2.3). On the
real PX4 SIH (five laps, alternating flights the same day) the shipped settings flew 0.4-0.6 cm/s
less than the earlier ones in every output mode (docs/controller.md, *The floor*).
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
def test_shipped_speed_loop_meets_the_target_where_the_earlier_one_did_not(tmp_path: Path) -> None:
    shipped_comp = yaml.safe_load(PX4_SIH.read_text())["compensation"]
    assert (shipped_comp["observer_rad_s"], shipped_comp["tangential_phase_margin_deg"]) == (4.0, 30.0)
    ct, rms, mean = _fly(tmp_path, "shipped", {})
    ct_old, rms_old, _ = _fly(tmp_path, "earlier", {"observer_rad_s": 8.0, "tangential_phase_margin_deg": 40.0})
    print(f"\npx4-sih rates: shipped {100 * ct:.1f} cm, {100 * rms:.1f} cm/s (mean {100 * mean:+.1f}); "
          f"observer 8 rad/s, margin 40 deg: {100 * ct_old:.1f} cm, {100 * rms_old:.1f} cm/s")
    assert rms < 0.05 and abs(mean) < 0.02 and ct < 0.05  # issue 8's targets
    assert rms < 0.85 * rms_old
