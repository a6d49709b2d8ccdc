"""A joint fit is not followed while hovering (control/adaptive.py, MIN_FIT_SPEED_M_S): after the
mock's px4-sih preset flies the held-out helix to its end (default config, ``rates`` output, the
preset's noisy estimate) and hovers there, the gain and drag it adopted stay, where followed they
drifted to the fit's prior (gain 0.99 -> 0.82, drag 0.98 -> 0 in 60 s) and the vertical command
rang at 5.4 Hz."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest

import pf_offboard.control.adaptive as adaptive
from pf_offboard.sim import SimSpec

from .truth import above_hz, fly_sampled

CONFIG = Path(__file__).resolve().parents[1] / "real_sitl" / "configs" / "helix.yaml"  # path and speed only


def _hover(tmp_path: Path) -> tuple[np.ndarray, Any]:
    """(time s, gain, drag 1/s, vertical command m/s^2) per following step over 90 s, and the compensator."""
    spec = SimSpec(autopilot="px4", vehicle="px4-sih", output_mode="rates", duration_s=90.0, rate_hz=50.0, seed=1)

    def sample(flight: Any, record: Any) -> tuple[float, ...]:
        c = flight.pipeline.follower.compensator
        return flight.autopilot.time_s, c.gain[0], c.drag[0], float(record.accel_cmd_enu_m_s2[2])

    a, flight = fly_sampled(CONFIG, spec, tmp_path, sample)
    return a, flight.pipeline.follower.compensator


def test_a_joint_fit_is_not_followed_while_hovering(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    a, comp = _hover(tmp_path)
    assert comp.identified is not None and comp.identified.delay_s > 0.1  # the joint model was adopted
    t = a[:, 0] - a[0, 0]
    end = (t > 40.0) & (t < 45.0)  # hovering at the path's end (it ends ~22 s after activation) ...
    late = t > 75.0  # ... and half a minute later
    assert abs(a[late, 1].mean() - a[end, 1].mean()) < 0.01 and abs(a[late, 2].mean() - a[end, 2].mean()) < 0.01
    assert a[late, 2].mean() > 0.5  # the drag it flew stays
    ringing = above_hz(t[late], a[late, 3])
    monkeypatch.setattr(adaptive, "MIN_FIT_SPEED_M_S", 0.0)  # followed as before
    (tmp_path / "before").mkdir()
    b, _ = _hover(tmp_path / "before")
    tb = b[:, 0] - b[0, 0]
    lb = tb > 75.0
    before = above_hz(tb[lb], b[lb, 3])
    print(f"hovering at the helix's end: gain {a[late, 1].mean():.3f}, drag {a[late, 2].mean():.3f}, vertical command "
          f"above 2.5 Hz {ringing:.2f} m/s^2 RMS (followed: gain {b[lb, 1].mean():.3f}, drag {b[lb, 2].mean():.3f}, {before:.2f})")  # fmt: skip
    assert b[lb, 2].mean() < 0.3 and before > 1.5 * ringing
