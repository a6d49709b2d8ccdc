"""tuning.margins_deg / real_vehicle_warning: gains judged against a real inner loop before flight."""

from __future__ import annotations

from pathlib import Path

import pytest

from pf_offboard.config import load_config
from pf_offboard.control.tuning import WARN_MARGIN_DEG, gains_for_vehicle, margins_deg, real_vehicle_warning
from pf_offboard.control.types import Gains, VehicleModel

ROOT = Path(__file__).resolve().parents[2]


def test_auto_gains_keep_the_margins_they_were_derived_for():
    for model in (VehicleModel.typical(), VehicleModel(accel_lag_xy_s=0.104, accel_delay_s=0.136)):
        for pm, pm_t in ((30.0, 40.0), (45.0, 30.0)):
            g = gains_for_vehicle(model, pm, pm_t)
            transversal, tangential = margins_deg(g, model, compensated=True)
            assert transversal == pytest.approx(pm, abs=0.05)
            assert tangential == pytest.approx(pm_t, abs=0.05)


def test_the_delay_counts_unless_compensated():
    g = gains_for_vehicle(VehicleModel.typical())
    with_prediction = margins_deg(g, VehicleModel.typical(), compensated=True)
    without = margins_deg(g, VehicleModel.typical(), compensated=False)
    assert without[0] < with_prediction[0] - 20.0 and without[1] < with_prediction[1] - 20.0


def test_the_papers_gains_are_flagged_for_a_real_vehicle():
    paper = load_config(ROOT / "configs" / "paper.yaml")  # ideal vehicle section, no compensation
    msg = real_vehicle_warning(paper.gains, paper.vehicle, paper.compensation.enabled)
    assert msg is not None
    assert "6 Hz" in msg and "typical" in msg and "ideal" in msg and "without the inner-loop compensation" in msg
    assert "-177 / -80 deg" in msg
    # with the compensation on a typical model (the shipped path configs before gains: auto)
    msg = real_vehicle_warning(Gains.paper(), VehicleModel.typical(), compensated=True)
    assert msg is not None and "-25 / 28 deg" in msg and "lag 0.1 s, delay 0.1 s" in msg


def test_the_default_gains_are_not_flagged():
    assert real_vehicle_warning(Gains(), VehicleModel.typical(), compensated=True) is None


@pytest.mark.parametrize("name", ["px4-sih", "arducopter", "figure8", "helix", "racetrack", "straight"])
def test_shipped_configs_for_real_vehicles_are_not_flagged(name):
    c = load_config(ROOT / "configs" / f"{name}.yaml")
    assert real_vehicle_warning(c.gains, c.vehicle, c.compensation.enabled) is None
    assert min(margins_deg(c.gains, c.vehicle, c.compensation.enabled)) >= WARN_MARGIN_DEG
