"""Issue 8's wind target on the realistic mock, through ``sim``: the shipped ``px4-sih.yaml`` in a
3 m/s wind with gusts stays within 6 cm cross-track RMS in every output mode.

Two laps from activation + 8 s, as issue 8 measures. The wind blows from the south (air moving
north, ENU (0, 3) m/s) with 0.5 m/s gusts (time constant 2 s), through the preset's linear drag
(1 s^-1): about 3 m/s^2 that the vehicle must lean into, which the disturbance observer learns.
Measured (seed 3): 3.10-3.15 cm and 4.61-4.66 cm/s (mean +0.1 cm/s) in each mode, the mean
commanded acceleration -2.4 m/s^2 northwards (observer 4 rad/s, the config before: 2.87-2.97 cm,
4.70-4.78 cm/s; 2.75-2.86 cm, 4.85-4.96 cm/s with one latency for the preset's thrust and tilt; with the hand-set vehicle section before:
3.0-3.1 cm, 5.4-5.5 cm/s; without the wind 2.3 cm, 4.3 cm/s and -0.05 m/s^2, attitude).
The speed target (5 cm/s) is not asked in wind: gusts are a speed disturbance the law does not see
coming; the issue asks 6 cm of cross-track there.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from pf_offboard.sim import SimSpec, simulate

from .helpers import PX4_SIH, errors, late_records

WIND_ENU_M_S = (0.0, 3.0, 0.0)
GUSTS = (0.5, 2.0)  # std m/s, time constant s


@pytest.mark.parametrize("output_mode", ["acceleration", "attitude", "rates"])
def test_a_3_m_s_wind_with_gusts_stays_within_6_cm(tmp_path: Path, output_mode: str) -> None:
    spec = SimSpec(vehicle="px4-sih", output_mode=output_mode, laps=2.0, seed=3, wind_enu_m_s=WIND_ENU_M_S, wind_gusts=GUSTS)
    late = late_records(simulate(PX4_SIH, spec, tmp_path / output_mode).records)
    assert len(late) > 500
    ct, err = errors(late)
    ct_rms, err_rms, err_mean = (float(np.sqrt(np.mean(ct**2))), float(np.sqrt(np.mean(err**2))), float(np.mean(err)))
    lean_north = float(np.mean([r.accel_cmd_enu_m_s2[1] for r in late]))
    print(f"\n{output_mode}: {100 * ct_rms:.2f} cm, {100 * err_rms:.2f} cm/s (mean {100 * err_mean:+.2f}), lean {lean_north:+.2f} m/s^2")
    assert ct_rms <= 0.06  # issue 8: "with a 3 m/s wind <= 6 cm"
    assert abs(err_mean) <= 0.02  # no steady speed error: the observer took the wind
    assert err_rms <= 0.08
    assert lean_north < -1.5  # the wind was there, and the vehicle leaned into it
