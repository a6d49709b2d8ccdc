"""Fast off-path starts on the px4-sih mock (the closest the mock gets to the real PX4 SIH's
``real_sitl_campaign.py --starts``): engaged 1.5-2 m off the racetrack, moving 1.5-2.5 m/s away
from it, with the default config (path + speed). Judged as the issue judges the real ones: the
cross-track error converges to <= 10 cm (and stays there for 1 s) within 3 s of activation.

The two starts here took 3.06 and 3.12 s before the offset integrators were gated to the path's
neighbourhood (compensator.OFFSET_INTEGRAL_BAND_M): the approach wound them up and the vehicle
overshot the path by 11-12 cm after arriving; with the gate 2.04 and 2.44 s, overshoot <= 5 cm.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from pf_offboard.sim import SimSpec, simulate

ROOT = Path(__file__).resolve().parents[2]
RACETRACK = ROOT / "tests" / "real_sitl" / "configs" / "racetrack.yaml"


def _convergence_s(records) -> tuple[float | None, float]:
    """(first time after activation from which the cross-track stays <= 10 cm for 1 s, the largest
    cross-track after first coming within 5 cm, m)."""
    act = [r for r in records if r.active]
    t0 = act[0].time_s
    conv = None
    for j, r in enumerate(act):
        window = [q for q in act[j:] if q.time_s <= r.time_s + 1.0]
        if act[-1].time_s >= r.time_s + 1.0 and all(q.cross_track_m <= 0.10 for q in window):
            conv = r.time_s - t0
            break
    first = next(j for j, r in enumerate(act) if r.cross_track_m <= 0.05)
    return conv, max(r.cross_track_m for r in act[first:])


@pytest.mark.parametrize("throw", [
    (-0.28, 2.57, 2.62, -0.04, 1.50, -0.01),  # 1.6 m off, 1.5 m/s away (a real PX4 SIH start's activation)
    (4.5, 0.0, 2.0, 2.5, 0.0, 0.5),  # 1.3 m beyond the end of the straight's turn, 2.5 m/s away, climbing
])
def test_fast_off_path_start_converges_within_3_s(tmp_path: Path, throw: tuple[float, ...]) -> None:
    res = simulate(RACETRACK, SimSpec(vehicle="px4-sih", output_mode="acceleration", throw_enu=throw, throw_engage_after_s=0.0,
                                      duration_s=7.0), tmp_path)  # fmt: skip
    assert not res.crashed
    conv, overshoot = _convergence_s(res.records)
    assert conv is not None and conv <= 2.7, conv  # 3.06 / 3.12 s with the approach winding up the integrators
    assert overshoot <= 0.08, overshoot  # 0.12 / 0.11 m then
