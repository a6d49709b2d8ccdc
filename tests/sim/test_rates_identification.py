"""The ``rates`` output over ArduCopter identifies a longer lag in flight (app.pipeline.fit_identification_to_output):
ArduCopter flies body rates through its own attitude target, so under the app's attitude loop the
horizontal response is a longer lag (0.15 s) with a short dead time, which the typical model's
lag with any shorter dead time cannot describe. On the mock's arducopter preset (lag 0.15 s + dead
time 0.08 s as the bank sees it) the bank now adopts it and the held-out figure-eight flies closer;
judged from the mock's truth (tests/sim/truth.py), default config, 50 Hz in-process flights."""

from __future__ import annotations

from pathlib import Path

import pytest

import pf_offboard.app.pipeline as pipeline
import pf_offboard.control.compensator as compensator
from pf_offboard.sim import SimSpec

from .heldout import write_config
from .truth import TruthMetrics, fly_truth, truth_metrics


def _fly(tmp_path: Path, path: str) -> tuple[TruthMetrics, object]:
    config = write_config(tmp_path, path, 1.5, None)
    spec = SimSpec(autopilot="ardupilot", vehicle="arducopter", output_mode="rates", duration_s=20.0, rate_hz=50.0, seed=1)
    flights: list = []
    m = truth_metrics(fly_truth(config, spec, tmp_path, patch=flights.append), 8.0)
    assert not m.crashed and m.window_s > 5.0
    return m, flights[0].pipeline.follower.compensator.identified


def test_the_arducopter_rates_output_adopts_the_longer_lag_and_flies_closer(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    m, model = _fly(tmp_path, "figure8-tilted")
    assert model is not None and (model.lag_s, model.delay_s) == (0.15, 0.08) and model.adopted_at_s <= 4.0
    monkeypatch.setattr(pipeline, "fit_identification_to_output", lambda *args: None)  # the bank as before
    monkeypatch.setattr(compensator, "DELAYS_S", tuple(d for d in compensator.DELAYS_S if d <= 0.1))  # no joint bank
    (tmp_path / "before").mkdir()
    before, before_model = _fly(tmp_path / "before", "figure8-tilted")
    print(f"figure-eight rates: cross-track RMS {100 * m.cross_track_rms_m:.2f} cm (before {100 * before.cross_track_rms_m:.2f}), "
          f"speed error RMS {100 * m.speed_error_rms_m_s:.2f} cm/s (before {100 * before.speed_error_rms_m_s:.2f})")  # fmt: skip
    assert before_model is None or before_model.lag_s == 0.1
    # measured: 0.68 cm, 0.79 cm/s; before 0.97 cm, 0.88 cm/s
    assert m.cross_track_rms_m <= 0.8 * before.cross_track_rms_m and m.cross_track_rms_m <= 0.008
    assert m.speed_error_rms_m_s <= before.speed_error_rms_m_s + 0.001 and m.speed_error_rms_m_s <= 0.01
