"""The in-process benchmark runs and reports its figures (speed is printed, never asserted)."""

from __future__ import annotations

import math

from sitl_mock.dynamics.bench import run_inprocess


def test_run_inprocess_quick_reports_consistent_figures() -> None:
    out = run_inprocess(quick=True)
    assert out["physics_rate_hz"] == 1000
    us_keys = [k for k in out if k.endswith("_us_per_tick")]
    assert len(us_keys) >= 4
    for k in us_keys:
        us = out[k]
        x = out[k.replace("_us_per_tick", "_x_realtime")]
        assert us > 0 and math.isfinite(us)
        assert math.isclose(x, 1e3 / us, rel_tol=1e-9)  # × real time of 1 kHz ticks
