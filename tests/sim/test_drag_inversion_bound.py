"""A wrong drag adopted in flight must not make the vehicle run away (issue 24, safety).

Real PX4 SIH flew the 3 m/s helix (attitude output) away once after the joint bank adopted drag
0.94 1/s: the compensator inverted the drag at the predicted velocity, positive velocity feedback
that outgrew the law's bounded tangential correction (3.9 m/s against 2.4, fence exit). Here the
px4-sih mock flies the same helix with a drag of 3 1/s (the fit's upper bound; the preset's is 1)
forced in as if adopted 3 s after activation. Measured from the mock's truth: inverting the drag
at the velocity (8d3a581) ran away, 9.7 m/s and 52 m off the path; with the drag fed forward at
the reference velocity and the deviation's share bounded (compensator.MAX_DRAG_FEEDBACK_M_S2)
0.46 m at most, 3.2 m/s at most (compensator.overspeed_bounded on top)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest

import pf_offboard.control.compensator as compensator
from pf_offboard.path import Projector
from pf_offboard.sim import SimSpec

from .truth import fly_truth

HELIX = Path(__file__).resolve().parents[1] / "real_sitl" / "configs" / "helix.yaml"
FORCED_AFTER_S = 3.0


def _force(drag: float, gain: float) -> Any:
    def _adapt(self: compensator.InnerLoopCompensator, t_prev: float, time_s: float, velocity: Any) -> None:
        t0 = self.__dict__.setdefault("_forced_t0", time_s)
        if time_s - t0 > FORCED_AFTER_S:  # what an adoption does, to this model
            self._move_to_target(time_s - t_prev, (self.lag[0], self.delay_s), drag, gain, (gain, drag))
    return _adapt


# (drag 1/s, gain, cross-track max m, speed max m/s) asserted; measured now / on 8d3a581:
# drag 3, gain 1: 0.46 m, 3.23 m/s / 52 m, 9.73; the fit's corners with the gain wrong too, gain 0.5:
# 1.85 m, 4.81 / 59 m, 9.80; gain 1.5: 1.79 m, 4.37 / 37 m, 9.63 (bounded, but not flown well: a
# wrong gain is not bounded by this)
CASES = [(3.0, 1.0, 1.0, 3.8), (3.0, 0.5, 2.5, 5.5), (3.0, 1.5, 2.5, 5.5)]


@pytest.mark.parametrize(("drag", "gain", "max_cross_m", "max_speed_m_s"), CASES)
def test_a_wrong_drag_adopted_in_flight_does_not_run_the_3ms_helix_away(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, drag: float, gain: float, max_cross_m: float, max_speed_m_s: float
) -> None:
    config = tmp_path / "helix-3ms.yaml"
    config.write_text(HELIX.read_text() + "speed_profile:\n  max_speed_m_s: 3.0\n")
    monkeypatch.setattr(compensator.InnerLoopCompensator, "_adapt", _force(drag, gain))
    spec = SimSpec(autopilot="px4", vehicle="px4-sih", output_mode="attitude", duration_s=30.0, rate_hz=50.0, seed=1)
    flights: list = []
    f = fly_truth(config, spec, tmp_path, patch=flights.append)
    comp = flights[0].pipeline.follower.compensator
    assert comp.drag == (drag, drag, drag) and comp.gain == pytest.approx((gain, gain, gain))  # the wrong model was flown
    t, p = f.time_s, f.position_enu_m
    proj = Projector(f.path)
    sig = np.array([f.path.eval(float(proj.update(x))).sigma for x in p])
    cross = np.linalg.norm(p - sig, axis=1)
    speed = np.r_[np.nan, np.linalg.norm(np.diff(p, axis=0), axis=1) / np.diff(t)]
    win = (t >= f.activation_s + FORCED_AFTER_S) & (np.abs(f.speed_ref_m_s) > 0.5)
    assert not f.crashed and t[-1] >= 29.9 and win.sum() > 300
    print(f"forced drag {drag} 1/s, gain {gain}: cross-track max {100 * cross[win].max():.1f} cm, speed max {np.nanmax(speed[win]):.2f} m/s "
          f"(reference at most {np.max(f.speed_ref_m_s):.2f})")  # fmt: skip
    assert cross[win].max() < max_cross_m
    assert np.nanmax(speed[win]) < max_speed_m_s
