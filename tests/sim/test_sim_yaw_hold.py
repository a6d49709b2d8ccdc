"""``yaw: {mode: hold}`` keeps the heading the vehicle has at activation: the follower takes it from
the attitude estimate when following starts (app.pipeline), logs it, and the vehicle does not turn;
the default constant heading (east) turns the mock vehicle, which starts facing north, by 90°.
Default config plus the yaw section, px4-sih preset, in-process flights judged from the mock's truth."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from pf_offboard.sim import SimSpec
from pf_offboard.sim.flight import SimFlight
from sitl_mock.rotations import euler_from_q

from .heldout import write_config
from .truth import fly_truth, truth_metrics


def _fly(tmp_path: Path, yaw: str | None, output: str) -> tuple[Any, list[float], Any]:
    config = write_config(tmp_path, "racetrack", 1.5, None)
    if yaw is not None:
        config.write_text(config.read_text(encoding="utf-8") + yaw + "\n", encoding="utf-8")
    spec = SimSpec(vehicle="px4-sih", output_mode=output, duration_s=12.0, rate_hz=50.0, seed=1)
    headings: list[float] = []
    flights: list[SimFlight] = []

    def patch(flight: SimFlight) -> None:
        flights.append(flight)
        step = flight.autopilot.step

        def recorded(dt_s: float):  # type: ignore[no-untyped-def]
            events = step(dt_s)
            headings.append(euler_from_q(flight.autopilot.truth.q_ned_frd)[2])  # NED yaw
            return events

        flight.autopilot.step = recorded

    truth = fly_truth(config, spec, tmp_path, patch=patch)
    return truth, headings, flights[0]


@pytest.mark.parametrize("output", ["acceleration", "rates"])
def test_hold_keeps_the_heading_at_activation_and_the_default_turns(tmp_path: Path, output: str) -> None:
    (tmp_path / "hold").mkdir()
    truth, headings, flight = _fly(tmp_path / "hold", "yaw: {mode: hold}", output)
    m = truth_metrics(truth, 6.0)
    assert not m.crashed and m.estimate_cross_track_rms_m < 0.03  # (the preset's estimate is offset from the truth)
    start = headings[0]
    turned = max(abs(math.remainder(h - start, 2 * math.pi)) for h in headings)
    held = flight.pipeline.follower._yaw.offset  # ENU
    assert abs(math.remainder(held - (math.pi / 2 - start), 2 * math.pi)) < math.radians(1.0)  # the heading it had
    assert turned < math.radians(10.0), math.degrees(turned)  # the tilt's coupling only (measured 0-5°)
    (tmp_path / "default").mkdir()
    _, default_headings, _ = _fly(tmp_path / "default", None, output)
    # the default (constant 0: east) turns the north-facing vehicle by ~90°
    assert abs(math.remainder(default_headings[-1] - (math.pi / 2), 2 * math.pi)) < math.radians(3.0)
    assert abs(math.remainder(default_headings[0] - start, 2 * math.pi)) < 1e-6


def test_the_activation_logs_the_heading_held(tmp_path: Path) -> None:
    from pf_offboard.sim import simulate

    config = write_config(tmp_path, "racetrack", 1.5, None)
    config.write_text(config.read_text(encoding="utf-8") + "yaw: {mode: hold}\n", encoding="utf-8")
    result = simulate(config, SimSpec(vehicle="px4-sih", duration_s=1.0, rate_hz=50.0, seed=1), tmp_path / "out")
    events = [r.event for r in result.records if r.event]
    assert "heading_held=" in events[0]
    held_deg = float(events[0].split("heading_held=")[1].split(";")[0])
    following = [r for r in result.records if r.mode == "following"]
    assert all(r.yaw_cmd_rad == pytest.approx(math.radians(held_deg), abs=2e-3) for r in following)
    assert np.all(np.array([r.yaw_rate_cmd_rad_s for r in following]) == 0.0)
