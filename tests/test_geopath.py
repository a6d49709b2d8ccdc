"""Way-points from planning tools: every format parses to the same local path; bad files are one
line naming the file, the item / line and the reason (exit 2)."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from pf_offboard.cli import main
from pf_offboard.config import load_config, with_origin
from pf_offboard.errors import InputError
from pf_offboard.geo import GeoPoint, enu_to_geodetic
from pf_offboard.geopath import MAX_DISTANCE_FROM_ORIGIN_M, PathFileError, check_distance_from_origin, read_geopath, to_local

DATA = Path(__file__).resolve().parent / "data" / "geo"
HOME = GeoPoint(-35.363261, 149.165230, 584.0)  # the samples' home (ArduPilot SITL's default)
EXPECTED_ENU_M = np.loadtxt(DATA / "expected_local_enu_m.txt")
FORMATS = ("plan", "waypoints", "csv", "geojson", "kml")


@pytest.mark.parametrize("fmt", FORMATS)
def test_every_format_gives_the_same_local_path_within_1_cm(fmt: str) -> None:
    geo = read_geopath(DATA / f"mission.{fmt}")
    local = to_local(geo, "relative_home", HOME)
    assert local.shape == EXPECTED_ENU_M.shape
    assert np.max(np.linalg.norm(local - EXPECTED_ENU_M, axis=1)) < 0.01
    reference = to_local(read_geopath(DATA / "mission.plan"), "relative_home", HOME)
    assert np.max(np.linalg.norm(local - reference, axis=1)) < 0.01


def test_plan_and_waypoints_skip_takeoff_speed_and_return_items() -> None:
    plan = read_geopath(DATA / "mission.plan")
    assert plan.altitude_reference == "relative_home"
    assert [s.split(" (")[0] for s in plan.skipped] == ["item 0", "item 1", "item 9"]
    assert plan.waypoints[0].where == "item 2"
    wpl = read_geopath(DATA / "mission.waypoints")
    assert wpl.altitude_reference == "relative_home" and wpl.skipped == ("line 3 (NAV_TAKEOFF)",)
    assert len(wpl.waypoints) == 7  # home (index 0) is not a way-point


def test_waypoints_with_crlf_and_trailing_tabs(tmp_path) -> None:
    p = tmp_path / "m.waypoints"
    p.write_bytes((DATA / "mission.waypoints").read_text().replace("\n", "\t\r\n").encode())
    assert read_geopath(p).lat_lon_alt().tolist() == read_geopath(DATA / "mission.waypoints").lat_lon_alt().tolist()


def test_relative_home_uses_the_home_altitude_not_the_origin() -> None:
    geo = read_geopath(DATA / "mission.csv")
    a = to_local(geo, "relative_home", HOME)
    b = to_local(geo, "relative_home", HOME, home_alt_amsl_m=HOME.alt_amsl_m + 1.5)  # home 1.5 m above the EKF origin
    assert np.allclose(b[:, 2] - a[:, 2], 1.5, atol=1e-6)
    assert np.allclose(b[:, :2], a[:, :2], atol=1e-5)


def test_amsl_file_against_another_origin(tmp_path) -> None:
    """The same way-points written AMSL and read against an origin 12 m north-east and 3 m higher."""
    lla = enu_to_geodetic(EXPECTED_ENU_M, HOME)  # alt here is AMSL
    (tmp_path / "p.csv").write_text("lat,lon,alt\n" + "".join(f"{a:.9f},{b:.9f},{c:.4f}\n" for a, b, c in lla))
    origin_enu = np.array([12.0, 12.0, 3.0])
    origin = GeoPoint(*enu_to_geodetic(origin_enu, HOME)[0])
    local = to_local(read_geopath(tmp_path / "p.csv"), "amsl", origin)
    assert np.max(np.abs(local - (EXPECTED_ENU_M - origin_enu))) < 0.01


def _plan(tmp_path: Path, mutate) -> Path:
    data = json.loads((DATA / "mission.plan").read_text())
    mutate(data["mission"]["items"])
    p = tmp_path / "bad.plan"
    p.write_text(json.dumps(data))
    return p


def _set(i: int, key: str, value: object):
    def f(items: list) -> None:
        items[i][key] = value

    return f


def _param(i: int, k: int, value: object):
    def f(items: list) -> None:
        items[i]["params"][k] = value

    return f


BAD_PLANS = [
    (_set(4, "frame", 0), "item 4", "differs"),
    (_set(3, "frame", 10), "item 3", "terrain"),
    (_param(5, 4, 95.0), "item 5", "latitude 95"),
    (_param(6, 5, "x"), "item 6", "longitude must be a number"),
    (_set(2, "command", 17), "item 2", "mission command NAV_LOITER_UNLIM (17)"),
    (_set(7, "type", "ComplexItem"), "item 7", "complex item"),
]


@pytest.mark.parametrize(("mutate", "where", "reason"), BAD_PLANS)
def test_bad_plan_item_is_named(tmp_path, mutate, where: str, reason: str) -> None:
    p = _plan(tmp_path, mutate)
    with pytest.raises(PathFileError) as info:
        read_geopath(p)
    assert str(info.value).startswith(f"{p}: {where}: ")
    assert reason in str(info.value)


BAD_TEXT = [
    ("bad.csv", "lat,lon,alt\n-35.1,149.1,2\n-35.1,149.2\n", "line 3", "2 fields"),
    ("bad.csv", "lat,lon\n-35.1,149.1\n", "line 1", "no alt column"),
    ("bad.csv", "lat,lon,alt\n-35.1,149.1,2\n-35.1,abc,2\n", "line 3", "lon 'abc' is not a number"),
    ("bad.waypoints", "QGC WPL 110\n0\t1\t0\t16\t0\t0\t0\t0\t-35.36\t149.16\t584\t1\n1\t0\t3\t16\t0\t0\t0\t0\t-35.36\t149.16\t2\n",
     "line 3", "expected 12 fields"),
    ("bad.waypoints", "QGC WPL 99\n", "line 1", "not a QGC WPL 110 (or 100)"),
    ("bad.geojson", '{"type": "LineString", "coordinates": [[149.1, -35.1, 2], [149.1, -35.2]]}', "position 1", "no altitude"),
    ("bad.geojson", '{"type": "LineString", "coordinates": [[149.1, -35.1, 2], \n [149.1 -35.2]]}', "line 2", "not valid JSON"),
    ("bad.plan", '{"fileType": "Plan", "mission": {"items": [}}', "line 1", "not valid JSON"),
    ("bad.kml", "<kml><LineString><coordinates>149.1,-35.1,2 149.1,-35.2</coordinates></LineString></kml>", "coordinate 1", "lon,lat,alt"),
    ("bad.gpx", "", "", "unknown way-point file type"),
]


@pytest.mark.parametrize(("name", "text", "where", "reason"), BAD_TEXT)
def test_bad_text_files_are_named(tmp_path, name: str, text: str, where: str, reason: str) -> None:
    p = tmp_path / name
    p.write_text(text)
    with pytest.raises(PathFileError) as info:
        read_geopath(p)
    prefix = f"{p}: {where}: " if where else f"{p}: "
    assert str(info.value).startswith(prefix), str(info.value)
    assert reason in str(info.value)


def test_distance_bound_refuses_a_far_way_point() -> None:
    pts = np.array([[0.0, 0.0, 2.0], [10.0, 900.0, 2.0], [0.0, 1200.0, 2.0]])
    with pytest.raises(PathFileError, match=r"f: way-point 2: is 1200 m from the vehicle's origin"):
        check_distance_from_origin(pts, "f")
    check_distance_from_origin(pts[:2], "f")
    assert MAX_DISTANCE_FROM_ORIGIN_M == 1000.0


def test_plan_read_against_the_wrong_origin_is_refused() -> None:
    """The samples are in Canberra; the mock's default home is in Zurich: refused, not flown."""
    with pytest.raises(PathFileError, match=r"item \d+: is \d+ m from the vehicle's origin"):
        to_local(read_geopath(DATA / "mission.plan"), "relative_home", GeoPoint(47.397742, 8.545594, 488.0))


# ---------------------------------------------------------------------------------- config
def _config(tmp_path: Path, body: str, sample: str = "mission.plan") -> Path:
    shutil.copy(DATA / sample, tmp_path / sample)
    p = tmp_path / "geo.yaml"
    p.write_text(body.replace("SAMPLE", sample))
    return p


def test_config_with_origin_is_local_at_load_time(tmp_path) -> None:
    p = _config(tmp_path, "path:\n  file: SAMPLE\n  altitude_reference: relative_home\n  closed: true\n"
                          "  origin: [-35.363261, 149.165230, 584.0]\nspeed_m_s: 1.5\n")  # fmt: skip
    cfg = load_config(p)
    assert not cfg.needs_origin
    assert np.max(np.abs(np.array(cfg.path.waypoints_enu_m) - EXPECTED_ENU_M)) < 0.01


def test_config_without_origin_waits_for_the_vehicle(tmp_path) -> None:
    p = _config(tmp_path, "path:\n  file: SAMPLE\n  altitude_reference: relative_home\n  closed: true\nspeed_m_s: 1.5\n", "mission.geojson")
    cfg = load_config(p)
    assert cfg.needs_origin and cfg.path.waypoints_enu_m == ()
    local = with_origin(cfg, HOME)
    assert np.max(np.abs(np.array(local.path.waypoints_enu_m) - EXPECTED_ENU_M)) < 0.01


@pytest.mark.parametrize(
    ("body", "message"),
    [
        ("path:\n  file: SAMPLE\n  closed: true\n", "path.altitude_reference: missing (required with path.file)"),
        ("path:\n  file: SAMPLE\n  altitude_reference: above_ground\n", "path.altitude_reference: must be one of relative_home, amsl"),
        ("path:\n  file: SAMPLE\n  altitude_reference: amsl\n", "path.altitude_reference: is amsl, but"),
        ("path:\n  file: SAMPLE\n  altitude_reference: relative_home\n  waypoints: [[0, 0, 1], [1, 0, 1]]\n", "path.waypoints: cannot be combined"),
        ("path:\n  file: SAMPLE\n  altitude_reference: relative_home\n  origin: [-35.3, 149.1]\n", "path.origin: must be [lat_deg, lon_deg, alt_amsl_m]"),
        ("path:\n  file: missing.plan\n  altitude_reference: relative_home\n", "missing.plan: cannot read"),
        ("path:\n  waypoints: [[0, 0, 1], [1, 0, 1]]\n  altitude_reference: amsl\n", "path.altitude_reference: only applies"),
    ],
)
def test_config_errors_name_what_is_missing(tmp_path, body: str, message: str) -> None:
    with pytest.raises(InputError) as info:
        load_config(_config(tmp_path, body))
    assert message in str(info.value)


def test_bad_file_is_one_line_and_exit_2(tmp_path, capsys) -> None:
    p = _config(tmp_path, "path:\n  file: SAMPLE\n  altitude_reference: relative_home\n", "mission.csv")
    (tmp_path / "mission.csv").write_text("lat,lon,alt\n-35.36,149.16,2\n-35.36,149.17,two\n")
    code = main(["fly", "--connect", "udpin:127.0.0.1:9", "--config", str(p), "--airborne"])
    err = capsys.readouterr().err
    assert code == 2
    assert err.count("\n") == 1
    assert f"mission.csv: line 3: alt 'two' is not a number" in err


def test_sim_needs_an_origin(tmp_path, capsys) -> None:
    p = _config(tmp_path, "path:\n  file: SAMPLE\n  altitude_reference: relative_home\n  closed: true\n")
    assert main(["sim", "--config", str(p), "--out", str(tmp_path / "o")]) == 2
    assert "path.origin" in capsys.readouterr().err


def _wpl100(text_110: str) -> str:
    """The same mission in the older QGC WPL 100 layout (action codes 25 way-point, 24 take-off)."""
    out = ["QGC WPL 100"]
    actions = {16: 25, 22: 24}
    for line in text_110.splitlines()[1:]:
        seq, current, frame, cmd, p1, p2, p3, p4, lat, lon, alt, auto = line.split()
        out.append("\t".join([seq, frame, str(actions[int(cmd)]), p3, p4, p1, p2, current, lon, lat, alt, "0", auto]))
    return "\n".join(out) + "\n"


def test_waypoints_100_and_110_read_alike_through_pymavlink(tmp_path) -> None:
    v110 = read_geopath(DATA / "mission.waypoints")
    p = tmp_path / "old.waypoints"
    p.write_text(_wpl100((DATA / "mission.waypoints").read_text()))
    v100 = read_geopath(p)
    assert v100.lat_lon_alt().tolist() == v110.lat_lon_alt().tolist()
    assert v100.skipped == v110.skipped == ("line 3 (NAV_TAKEOFF)",)
    assert v100.takeoff_alt_m == v110.takeoff_alt_m == 2.0  # the take-off item's altitude above home


def test_plan_take_off_altitude_is_read_and_commands_are_named_from_pymavlink() -> None:
    from pf_offboard.geopath import command_name, frame_name

    plan = read_geopath(DATA / "mission.plan")
    assert plan.takeoff_alt_m is not None and plan.takeoff_alt_m > 0
    assert command_name(22) == "NAV_TAKEOFF" and command_name(206) == "DO_SET_CAM_TRIGG_DIST"
    assert command_name(65000) == "command 65000" and frame_name(10) == "GLOBAL_TERRAIN_ALT"
