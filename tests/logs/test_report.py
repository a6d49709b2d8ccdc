"""The flight report: summary.json beside the logs, --json on stdout, and the map-frame top view."""

from __future__ import annotations

import json
import math
import shutil
from pathlib import Path

import pytest

from pf_offboard.cli import main
from pf_offboard.logs.plot import Fence, fence_from_config, make_figures, plot_map, load_run
from pf_offboard.logs.measures import WindowFigures
from pf_offboard.logs.summary import FlightSummary, report_json

DATA = Path(__file__).resolve().parents[1] / "data" / "geo"


def _geo_config(tmp_path: Path) -> Path:
    shutil.copy(DATA / "mission.csv", tmp_path / "mission.csv")
    p = tmp_path / "geo.yaml"
    p.write_text("path:\n  file: mission.csv\n  altitude_reference: relative_home\n  closed: true\n"
                 "  origin: [-35.363261, 149.165230, 584.0]\nspeed_m_s: 1.5\nflight: {setpoint_rate_hz: 50}\n")  # fmt: skip
    return p


def test_sim_writes_summary_json_and_prints_it_with_json(tmp_path, capsys) -> None:
    config = _geo_config(tmp_path)
    code = main(["sim", "--config", str(config), "--start", "5,1.5,2", "--duration", "4", "--out", str(tmp_path / "o"), "--json"])
    assert code == 0
    printed = json.loads(capsys.readouterr().out)  # stdout is the JSON document and nothing else
    written = json.loads((tmp_path / "o" / "summary.json").read_text())
    assert printed == written
    assert written["schema"] == 1 and written["command"] == "sim" and written["exit_code"] == 0
    s = written["summary"]
    assert s["convergence_time_s"] is not None and 0.0 <= s["convergence_time_s"] < 4.0
    assert s["whole_flight"]["cross_track_rms_m"] < 0.05 and s["steps"] == 201
    assert s["from_activation_plus_8s"] is None  # a 4 s flight has no such window
    assert s["whole_flight"]["window"] == "whole flight" and s["whole_flight"]["speed_error_rms_m_s"] is not None
    assert written["path_file"]["origin"] == {"lat_deg": -35.363261, "lon_deg": 149.16523, "alt_amsl_m": 584.0}
    assert written["path_file"]["altitude_reference"] == "relative_home"
    # the log's config copy is local and self-contained: replay rebuilds the flown path bit for bit
    assert main(["replay", str(tmp_path / "o" / "flight.tlog"), "--json"]) == 0
    replayed = json.loads(capsys.readouterr().out)
    assert replayed["summary"] == written["summary"]


def test_report_json_is_strict() -> None:
    w = WindowFigures("whole flight", 0.0, 1.0, 2, 0.1, 0.2, math.nan, math.nan, math.inf, None, None)
    s = FlightSummary(1.0, 2, 2, 0.0, None, None, w, {"sat_tilt": 0.0}, (), ())
    text = report_json({"summary": s.to_dict()})
    assert "NaN" not in text and "Infinity" not in text
    assert json.loads(text)["summary"]["whole_flight"]["speed_error_rms_m_s"] is None


def test_plot_draws_the_map_view_with_the_fence(tmp_path, capsys) -> None:
    config = _geo_config(tmp_path)
    assert main(["sim", "--config", str(config), "--start", "5,1.5,2", "--duration", "2", "--out", str(tmp_path / "o")]) == 0
    capsys.readouterr()
    assert fence_from_config(tmp_path / "o" / "flight.yaml") is None  # no safety: section
    pngs = make_figures([tmp_path / "o" / "flight.csv"], tmp_path / "fig")
    assert "map.png" in {p.name for p in pngs}
    # a fence draws a box (the image differs from the one without)
    run = load_run(tmp_path / "o" / "flight.csv")
    a = plot_map([run], None, None, tmp_path / "a.png")
    b = plot_map([run], None, Fence(min_enu_m=(-1.0, -2.0, 0.0), max_enu_m=(9.0, 8.0, 5.0)), tmp_path / "b.png")
    assert a.read_bytes() != b.read_bytes()


@pytest.mark.parametrize(
    ("safety", "expected"),
    [
        ("safety:\n  fence_min_enu_m: [-3, -3, 0]\n  fence_max_enu_m: [3, 3, 4]\n", Fence(min_enu_m=(-3.0, -3.0, 0.0), max_enu_m=(3.0, 3.0, 4.0))),
        ("safety:\n  fence_center_enu_m: [1, 2]\n  fence_radius_m: 20\n", Fence(center_enu_m=(1.0, 2.0), radius_m=20.0)),
        ("safety:\n  enabled: true\n", None),
    ],
)
def test_fence_from_the_config_safety_section(tmp_path, safety: str, expected) -> None:
    p = tmp_path / "c.yaml"
    p.write_text("path:\n  waypoints: [[0, 0, 1], [1, 0, 1]]\n" + safety)
    assert fence_from_config(p) == expected
