"""YAML config schema: every shipped config loads; every bad input gives one ConfigError naming
the dotted field and the reason."""

from __future__ import annotations

import math
from pathlib import Path as FsPath

import pytest
import yaml

from pf_offboard import PathFollower, load_config, parse_config
from pf_offboard.config import Config, FlightConfig
from pf_offboard.control.tuning import gains_for_vehicle
from pf_offboard.control.types import VehicleModel
from pf_offboard.control.types import Gains, Limits
from pf_offboard.errors import ConfigError, InputError

ROOT = FsPath(__file__).resolve().parents[1]
SQUARE = [[0.0, 0.0, 2.0], [2.0, 0.0, 2.0], [2.0, 2.0, 2.5], [0.0, 2.0, 2.0]]


def minimal(**over) -> dict:
    d = {"path": {"closed": True, "waypoints": [list(p) for p in SQUARE]}}
    d.update(over)
    return d


@pytest.mark.parametrize("name", sorted(p.name for p in (ROOT / "configs").glob("*.yaml")))
def test_shipped_configs_load_and_build(name):
    cfg = load_config(ROOT / "configs" / name)
    assert isinstance(cfg, Config)
    f = PathFollower.from_config(cfg)
    assert f.speed == cfg.speed_m_s


def test_paper_config_is_the_paper_setting():
    cfg = load_config(ROOT / "configs" / "paper.yaml")
    assert cfg.speed_m_s == -1.5
    assert cfg.gains == Gains(6.0, 0.7, 4.0, 0.8)
    assert cfg.yaw.mode == "constant" and cfg.yaw.yaw_rad == 0.0
    assert cfg.path.closed and len(cfg.path.waypoints_enu_m) == 7


def test_defaults_for_everything_but_the_path():
    cfg = parse_config(minimal())
    assert cfg.speed_m_s == 1.0
    # no gains section: derived from the (typical) vehicle model, far below the paper's ideal ones
    assert cfg.gains_auto and cfg.vehicle == VehicleModel.typical()
    assert cfg.gains == gains_for_vehicle(
        VehicleModel.typical(), cfg.compensation.phase_margin_deg, cfg.compensation.tangential_phase_margin_deg
    )
    # the speed loop has its own margin (40°) and is not capped at the transversal bandwidth
    assert cfg.gains.tangential_bandwidth_hz > cfg.gains.transversal_bandwidth_hz
    assert 0.3 < cfg.gains.transversal_bandwidth_hz < Gains.paper().transversal_bandwidth_hz / 3
    assert cfg.gains == Gains()  # one source of truth: the core's defaults are the config's
    assert cfg.compensation.enabled
    assert cfg.limits == Limits()
    assert cfg.flight == FlightConfig()
    assert cfg.path.frame == "enu" and cfg.path.moving_frame == "auto"


def test_velocity_correction_is_the_autopilots_by_default_and_null_turns_it_off():
    import argparse

    from pf_offboard.app.fly import flight_settings
    from pf_offboard.app.profiles import ARDUPILOT, PX4

    no_flags = argparse.Namespace(output=None, end_action=None)
    default = flight_settings(parse_config(minimal()), no_flags)
    assert default.velocity_correction_s == "auto"
    # PX4's EKF2 velocity disagrees with its position: corrected fast; ArduPilot's EKF3 agrees
    assert default.velocity_correction_for(PX4) == 0.1 and default.velocity_correction_for(ARDUPILOT) == 0.3
    data = minimal()
    data["flight"] = {"velocity_correction_s": "auto"}
    assert parse_config(data).flight.velocity_correction_s == "auto"
    data["flight"] = {"velocity_correction_s": None}
    assert parse_config(data).flight.velocity_correction_s is None
    off = flight_settings(parse_config(data), no_flags)
    assert off.velocity_correction_for(PX4) is None and off.velocity_correction_for(ARDUPILOT) is None
    data["flight"] = {"velocity_correction_s": 0.5}
    fixed = flight_settings(parse_config(data), no_flags)
    assert fixed.velocity_correction_for(PX4) == 0.5 and fixed.velocity_correction_for(ARDUPILOT) == 0.5
    for bad in (0.01, "fast", True):
        data["flight"] = {"velocity_correction_s": bad}
        with pytest.raises(ConfigError, match="flight.velocity_correction_s"):
            parse_config(data)


def test_ned_waypoints_and_yaw_are_converted():
    ned = [[p[1], p[0], -p[2]] for p in SQUARE]
    cfg = parse_config(
        {"path": {"frame": "ned", "closed": True, "waypoints": ned}, "yaw": {"mode": "constant", "yaw_deg": 90.0}}
    )
    assert [list(p) for p in cfg.path.waypoints_enu_m] == SQUARE
    assert cfg.yaw.yaw_rad == pytest.approx(0.0, abs=1e-12)  # NED east = ENU 0
    cfg = parse_config(
        {
            "path": {"frame": "ned", "closed": True, "waypoints": ned},
            "yaw": {"mode": "table", "table": [[0.0, 0.0], [2.0, 90.0], [4.0, 180.0]]},
        }
    )
    psi = [p for _, p in cfg.yaw.table_eta1_m_yaw_rad]
    assert psi[0] == pytest.approx(math.pi / 2)
    assert psi[1] == pytest.approx(0.0, abs=1e-12)
    assert psi[2] == pytest.approx(-math.pi / 2)  # unwrapped: continuous, not +3 pi / 2
    cfg = parse_config({"path": {"frame": "ned", "closed": True, "waypoints": ned}, "yaw": {"mode": "tangent", "yaw_deg": 10.0}})
    assert cfg.yaw.yaw_rad == pytest.approx(-math.radians(10.0))  # clockwise offset in NED


BAD = [
    ({"path": None}, "path", "missing"),
    ({"pathh": {}}, "pathh", "unknown key"),
    (minimal(speed_m_s=0), "speed_m_s", "non-zero"),
    (minimal(speed_m_s=25.0), "speed_m_s", "<= 20"),
    (minimal(speed_m_s="fast"), "speed_m_s", "number"),
    (minimal(speed_m_s=True), "speed_m_s", "number"),
    (minimal(speed_m_s=float("nan")), "speed_m_s", "finite"),
    (minimal(gains={"transversal": {"bandwidth_hz": -1.0}}), "gains.transversal.bandwidth_hz", ">= 0.01"),
    (minimal(gains={"transversal": {"bandwidth_hz": 1e-320}}), "gains.transversal.bandwidth_hz", ">= 0.01"),
    (minimal(gains={"tangential": {"damping": 1e-320}}), "gains.tangential.damping", ">= 0.01"),
    (minimal(limits={"max_tilt_deg": 1e-320}), "limits.max_tilt_deg", ">= 1"),
    (minimal(speed_m_s=1e-320), "speed_m_s", "non-zero"),
    (minimal(speed_m_s=10**400), "speed_m_s", "out of range"),
    ({"path": {"waypoints": [[0, 0, 1], [1, 0, 1], [1, 10**400, 1]]}}, "path.waypoints[2]", "out of range"),
    (minimal(gains={"transversal": {"bandwith_hz": 6.0}}), "gains.transversal.bandwith_hz", "unknown key"),
    (minimal(gains={"tangential": {"damping": float("inf")}}), "gains.tangential.damping", "finite"),
    (minimal(gains=[1, 2]), "gains", "mapping"),
    (minimal(limits={"max_tilt_deg": 85.0}), "limits.max_tilt_deg", "<= 80"),
    (minimal(limits={"max_thrust_m_s2": 9.0}), "limits.max_thrust_m_s2", ">="),
    (minimal(limits={"min_thrust_m_s2": -1.0}), "limits.min_thrust_m_s2", ">= 0.5"),
    (minimal(limits={"min_thrust_m_s2": 0.0}), "limits.min_thrust_m_s2", ">= 0.5"),
    (minimal(limits={"max_approach_speed_m_s": 0.0}), "limits.max_approach_speed_m_s", ">="),
    (minimal(yaw={"mode": "spin"}), "yaw.mode", "one of"),
    (minimal(yaw={"mode": "table"}), "yaw.table", "at least 2"),
    (minimal(yaw={"mode": "hold", "yaw_deg": 30.0}), "yaw.yaw_deg", "not used with mode hold"),
    (minimal(yaw={"mode": "table", "table": [[0.0, 0.0], [0.0, 10.0]]}), "yaw.table[1]", "increasing"),
    (minimal(yaw={"mode": "table", "table": [[0.0, 0.0], [1.0]]}), "yaw.table[1]", "2 numbers"),
    (minimal(compensation={"tangential_phase_margin_deg": 5.0}), "compensation.tangential_phase_margin_deg", ">= 10"),
    (minimal(compensation={"tangential_phase_margin_deg": float("nan")}), "compensation.tangential_phase_margin_deg", "finite"),
    (minimal(feedforward="any_state"), "feedforward", "compensation.enabled: false"),
    (minimal(feedforward="any_state", compensation={"enabled": True}), "feedforward", "lag lead replaces"),
    (minimal(flight={"output_mode": "thrust"}), "flight.output_mode", "one of"),
    (minimal(flight={"setpoint_rate_hz": 10}), "flight.setpoint_rate_hz", ">= 20"),
    (minimal(flight={"hover_thrust": 1.2}), "flight.hover_thrust", "<= 0.95"),
    (minimal(flight={"end_action": "crash"}), "flight.end_action", "one of"),
    (minimal(flight={"state_timeout": 1.0}), "flight.state_timeout", "unknown key"),
    ({"path": {"closed": True}}, "path.waypoints", "missing"),
    ({"path": {"closed": "yes", "waypoints": SQUARE}}, "path.closed", "true or false"),
    ({"path": {"frame": "xyz", "waypoints": SQUARE}}, "path.frame", "one of"),
    ({"path": {"moving_frame": "bishop", "waypoints": SQUARE}}, "path.moving_frame", "one of"),
    ({"path": {"waypoints": [[0, 0, 1], [1, 0, 1], [1, 1, 1], [1, 1]]}}, "path.waypoints[3]", "3 numbers"),
    ({"path": {"waypoints": [[0, 0, 1], [1, 0, 1], [1, "a", 1]]}}, "path.waypoints[2]", "3 numbers"),
    ({"path": {"waypoints": [[0, 0, 1], [1, 0, 1], [1, float("nan"), 1]]}}, "path.waypoints[2]", "finite"),
    ({"path": {"waypoints": [[0, 0, 1], [1, 0, 1], [1, 0, 1], [2, 2, 2]]}}, "path.waypoints[2]", "duplicate"),
    ({"path": {"closed": True, "waypoints": [[0, 0, 1], [1, 0, 1]]}}, "path.waypoints", "at least 3"),
    ({"path": {"moving_frame": "frenet", "waypoints": [[0, 0, 1], [1, 1, 1], [2, 2, 1]]}}, "path.moving_frame", "frenet"),
    ([1, 2, 3], "<config>", "mapping"),
]


@pytest.mark.parametrize("data,field,reason", BAD, ids=[b[1] + ":" + b[2] for b in BAD])
def test_bad_values_name_field_and_reason(data, field, reason):
    with pytest.raises(ConfigError) as err:
        parse_config(data)
    assert err.value.field == field
    assert reason in err.value.reason
    assert isinstance(err.value, InputError)


def test_yaml_syntax_error_has_line_number(tmp_path):
    p = tmp_path / "bad.yaml"
    p.write_text("path:\n  closed: true\n  waypoints: [[0, 0, 1], [1, 0, 1]\nspeed_m_s: 1.0\n")
    with pytest.raises(ConfigError) as err:
        load_config(p)
    assert err.value.field == str(p)
    assert "line " in err.value.reason and "syntax" in err.value.reason


def test_duplicate_key_is_an_error(tmp_path):
    p = tmp_path / "dup.yaml"
    p.write_text(yaml.safe_dump(minimal()) + "speed_m_s: 1.0\nspeed_m_s: 2.0\n")
    with pytest.raises(ConfigError) as err:
        load_config(p)
    assert err.value.field == "speed_m_s" and "duplicate" in err.value.reason


def test_missing_file_and_empty_file(tmp_path):
    with pytest.raises(ConfigError) as err:
        load_config(tmp_path / "nope.yaml")
    assert "cannot read" in err.value.reason
    p = tmp_path / "empty.yaml"
    p.write_text("# nothing\n")
    with pytest.raises(ConfigError) as err:
        load_config(p)
    assert err.value.field == "path"


def test_yaml_nan_is_rejected(tmp_path):
    p = tmp_path / "nan.yaml"
    p.write_text(yaml.safe_dump(minimal()) + "limits: {max_tilt_deg: .nan}\n")
    with pytest.raises(ConfigError) as err:
        load_config(p)
    assert err.value.field == "limits.max_tilt_deg" and "finite" in err.value.reason


def test_round_trip_file(tmp_path):
    p = tmp_path / "ok.yaml"
    p.write_text(yaml.safe_dump(minimal(speed_m_s=-2.0, flight={"hover_thrust": None, "output_mode": "rates"})))
    cfg = load_config(p)
    assert cfg.speed_m_s == -2.0 and cfg.flight.output_mode == "rates" and cfg.flight.hover_thrust is None
    assert cfg.source == str(p)


NUMERIC_FIELDS = [
    ("speed_m_s",),
    ("gains", "transversal", "bandwidth_hz"),
    ("gains", "transversal", "damping"),
    ("gains", "tangential", "bandwidth_hz"),
    ("gains", "tangential", "damping"),
    ("yaw", "yaw_deg"),
    ("limits", "max_tilt_deg"),
    ("limits", "min_thrust_m_s2"),
    ("limits", "max_thrust_m_s2"),
    ("limits", "max_approach_speed_m_s"),
    ("limits", "max_tilt_rate_rad_s"),
    ("limits", "max_tangential_accel_m_s2"),
    ("flight", "setpoint_rate_hz"),
    ("flight", "state_timeout_s"),
    ("flight", "hover_thrust"),
    ("flight", "takeoff_altitude_m"),
    ("flight", "throw_activation_height_m"),
    ("flight", "attitude_time_constant_s"),
    ("flight", "velocity_correction_s"),
]


def _with(keys: tuple[str, ...], value) -> dict:
    data = minimal()
    d = data
    for k in keys[:-1]:
        d = d.setdefault(k, {})
    d[keys[-1]] = value
    return data


@pytest.mark.parametrize("keys", NUMERIC_FIELDS, ids=[".".join(k) for k in NUMERIC_FIELDS])
@pytest.mark.parametrize(
    "value,reason",
    [(math.nan, "finite"), (math.inf, "finite"), (-math.inf, "finite"), ("fast", "number"), (True, "number"),
     ([1.0], "number")],
    ids=["nan", "inf", "-inf", "string", "bool", "list"],
)
def test_every_numeric_field_rejects_non_numbers_and_non_finite(keys, value, reason):
    """Every numeric field of every section: NaN/inf and non-numbers give one ConfigError naming
    the dotted field and the reason (never a default silently used, never a crash)."""
    with pytest.raises(ConfigError) as err:
        parse_config(_with(keys, value))
    assert err.value.field == ".".join(keys)
    assert reason in err.value.reason


def test_every_numeric_field_is_in_the_schema():
    """The list above covers every numeric field the schema has (a new field needs a row)."""
    from dataclasses import fields

    covered = {k[-1] for k in NUMERIC_FIELDS}
    schema = {f.name for f in fields(FlightConfig) if f.type in ("float", "float | None", "float | str | None")}
    schema |= {f.name for f in fields(Limits)}
    assert len(schema) == 13
    assert schema <= covered, schema - covered


@pytest.mark.parametrize("section", ["gains", "yaw", "limits", "flight", "path"])
def test_every_section_must_be_a_mapping(section):
    with pytest.raises(ConfigError) as err:
        parse_config(minimal(**{section: [1, 2]}))
    assert err.value.field == section and "mapping" in err.value.reason


def test_a_config_that_is_not_a_mapping_names_the_file(tmp_path):
    bad = tmp_path / "list.yaml"
    bad.write_text("- [0, 0, 1]\n- [1, 0, 1]\n")
    with pytest.raises(ConfigError) as err:
        load_config(bad)
    assert err.value.field == str(bad)
    assert "must be a mapping of sections" in err.value.reason


def test_yaw_hold_and_a_table_without_a_mode() -> None:
    wp = [[0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]]
    cfg = parse_config({"path": {"waypoints": wp, "closed": True}, "yaw": {"mode": "hold"}})
    assert cfg.yaw.mode == "hold"
    assert parse_config({"path": {"waypoints": wp, "closed": True}}).yaw.mode == "constant"  # the default: 0, east
    cfg = parse_config({"path": {"waypoints": wp, "closed": True}, "yaw": {"table": [[0.0, 0.0], [1.0, 90.0]]}})
    assert cfg.yaw.mode == "table" and cfg.yaw.table_eta1_m_yaw_rad[1][1] == pytest.approx(math.pi / 2)
