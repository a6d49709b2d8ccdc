"""Estimator plausibility against sitl-mock over real loopback UDP (issue 9, item 5, the parts on
implausible jumps): a 50 m jump of the autopilot's position estimate mid-flight."""

from __future__ import annotations

import numpy as np
import pytest
import yaml
from sitl_mock.config import FaultConfig
from sitl_mock.runner import run_in_thread
from sitl_mock.testing import free_udp_port

from app.flights import write_config

from .attackers import fly_udpin, mock_config

pytestmark = pytest.mark.integration


def test_a_50_m_estimator_jump_is_refused_then_flagged_as_an_estimator_reset(tmp_path) -> None:
    """LOCAL_POSITION_NED jumps 50 m north at t = 5 s (the vehicle does not move). The first jumped
    sample is refused (never flown); the next confirms it, and it is accepted as an estimator reset,
    counted (``Estimator.rejected_jumps`` / ``position_resets``) and reported; the envelope ends
    following on it (larger than safety.max_estimator_reset_m) and the hold is confirmed."""
    app_port = free_udp_port()
    # the envelope (issue 9) would end following on the jumped position (tests/faults/test_fence.py):
    # a fence wide enough for the jump isolates the estimator's own behaviour
    config = write_config(tmp_path)
    data = yaml.safe_load(config.read_text())
    data["safety"] = {"fence_margin_m": 100.0, "max_path_distance_m": 100.0}
    config.write_text(yaml.safe_dump(data))
    faults = FaultConfig(estimator_reset_at_s=5.0, estimator_reset_ned_m=(50.0, 0.0, 0.0))
    with run_in_thread(mock_config(app_port, faults=faults)) as mock:
        outcome, printed = fly_udpin(app_port, config, tmp_path / "log", "--airborne", "--duration", "5.5")
        mode = mock.call(lambda m: m.autopilot.mode.name)
    est = outcome.estimator
    assert est.rejected_jumps == 1 and est.position_resets == 1, est.last_event
    # the jump is refused on its first sample; confirmed by the next, it is a 50 m estimator reset:
    # larger than safety.max_estimator_reset_m, following ends there, never flown towards it
    assert outcome.exit_code == 5 and "estimator reset moved the position estimate 50.00 m" in outcome.reason, printed
    assert "AUTO.LOITER requested, confirmed" in outcome.reason
    assert 5.0 <= outcome.breach_time_s <= 5.05
    positions = np.array([r.position_enu_m for r in outcome.records])
    assert np.abs(positions[:, 1]).max() < 5.0  # no step ever saw the jumped position (ENU y = NED north)
    assert "1 position jumps (1 confirmed as resets)" in printed
    assert mode == "AUTO.LOITER"
