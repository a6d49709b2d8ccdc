"""What the inner-loop identification adopted (``compensation.identify_online``, on by default) is
in the flight's step log, ``summary.json`` and the replay's summary: a default config (path and
speed only) on the ``fast`` preset, whose response has no dead time (the typical model says
0.1 s), adopts a shorter one; on the px4-sih preset (slower than the guess) a longer one with its
fitted gain and drag, whose gains and vertical drag are logged too; null when nothing is adopted
(a flight too short to settle)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import yaml

from pf_offboard import cli
from pf_offboard.logs.steplog import read_steplog

from .helpers import PX4_SIH


def _default_config(tmp: Path) -> Path:
    data = yaml.safe_load(PX4_SIH.read_text(encoding="utf-8"))
    data.pop("vehicle")
    data.pop("compensation")  # the defaults: the typical model, identified in flight
    # the velocity correction this 10 s flight adopts with: at the 0.1 s default the identifier fits
    # a velocity with more of the mock estimate's position noise and this short flight adopts
    # nothing (the held-out figure-eights still adopt at 6 s); this test is about the logging
    data.setdefault("flight", {})["velocity_correction_s"] = 0.3
    out = tmp / "default.yaml"
    out.write_text(yaml.safe_dump(data), encoding="utf-8")
    return out


@pytest.mark.parametrize("vehicle,adopts,seconds", [("fast", "shorter", 8), ("px4-sih", "longer", 10), ("px4-sih", None, 5)])
def test_the_identified_model_is_logged_summarised_and_replayed(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                                vehicle: str, adopts: str | None, seconds: int) -> None:  # fmt: skip
    out = tmp_path / "flight"
    code = cli.main(["sim", "--config", str(_default_config(tmp_path)), "--vehicle", vehicle, "--duration", str(seconds), "--out", str(out)])
    assert code == 0
    text = capsys.readouterr().out
    model = json.loads((out / "summary.json").read_text(encoding="utf-8"))["summary"]["identified_model"]
    events = [r for r in read_steplog(out / "flight.csv") if "identified: " in r.event]
    assert code == cli.main(["replay", str(out / "flight.tlog"), "--json"])
    replayed = json.loads(capsys.readouterr().out)
    assert replayed["summary"]["identified_model"] == model
    if not adopts:
        assert model is None and not events and "identified model    none adopted" in text
        return
    assert model is not None and len(events) >= 1
    assert model["adopted_at_s"] == events[-1].time_s and 3.0 <= model["adopted_at_s"] <= seconds
    assert model["lag_s"] == 0.1 and 0.0 <= model["drag_1_s"] <= 3.0
    assert f"dead time {model['delay_s']:.3f} s" in text
    if adopts == "shorter":
        assert model["delay_s"] < 0.1 and "gain_xy" not in model  # the bank's: the model's gain
        return
    # the joint bank's: a longer dead time, its gain and drag on every axis, after 6 s of data
    assert model["delay_s"] > 0.1 and model["adopted_at_s"] >= 6.0 and 0.5 <= model["gain_xy"] <= 1.5
    assert (model["gain_z"], model["drag_z_1_s"]) == (model["gain_xy"], model["drag_1_s"])
    assert f"gain {model['gain_xy']:.3f}; vertical gain" in text
