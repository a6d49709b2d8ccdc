"""What the inner-loop identification adopted (``compensation.identify_online``, on by default) is
in the flight's step log, ``summary.json`` and the replay's summary: a default config (path and
speed only) on the ``fast`` preset, whose response has no dead time (the typical model says
0.1 s), adopts a shorter one; on the px4-sih preset (slower than the guess) nothing is adopted:
null."""

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
    out = tmp / "default.yaml"
    out.write_text(yaml.safe_dump(data), encoding="utf-8")
    return out


@pytest.mark.parametrize("vehicle,adopts", [("fast", True), ("px4-sih", False)])
def test_the_identified_model_is_logged_summarised_and_replayed(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                                vehicle: str, adopts: bool) -> None:  # fmt: skip
    out = tmp_path / "flight"
    code = cli.main(["sim", "--config", str(_default_config(tmp_path)), "--vehicle", vehicle, "--duration", "8", "--out", str(out)])
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
    assert model["lag_s"] == 0.1 and model["delay_s"] < 0.1 and 0.0 <= model["drag_1_s"] <= 3.0
    assert model["adopted_at_s"] == events[-1].time_s and 3.0 <= model["adopted_at_s"] <= 8.0
    assert f"dead time {model['delay_s']:.3f} s" in text
