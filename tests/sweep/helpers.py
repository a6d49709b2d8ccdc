"""Tiny sweeps for the tests: short flights on the paper path (the fast preset), a few starts."""

from __future__ import annotations

from pathlib import Path

from pf_offboard.sweep import FlightSettings, StartRanges, SweepSpec

ROOT = Path(__file__).resolve().parents[2]
PAPER = ROOT / "configs" / "paper.yaml"
PX4_SIH = ROOT / "configs" / "px4-sih.yaml"
# 1.5 s of flight at 50 Hz: enough to engage, approach and judge; ~0.1 s of CPU each
TINY = FlightSettings(vehicle="fast", duration_s=1.5, rate_hz=50.0, tube_m=0.3, stay_m=1.0, settle_s=0.2)


def tiny_spec(flights: int = 4, seed: int = 7) -> SweepSpec:
    return SweepSpec(flights=flights, seed=seed, ranges=StartRanges(max_distance_m=1.0, max_speed_m_s=1.0), settings=TINY)
