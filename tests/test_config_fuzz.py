"""Property-based fuzzing of the config loader and the way-point parser (issue 9, item 8).

Bad input must end in one :class:`InputError` / :class:`ConfigError` naming the field (the CLI
prints it as one line, exit 2), never a traceback. Three generators, 700 + 700 + 500 examples:

- structured: a valid config with random fields replaced by random YAML values (huge integers
  written as digits, subnormal floats such as 1e-320, NaN / inf, strings, lists, mappings,
  missing sections) — what reaches the field validators and, when it loads, the controller's
  constructor (a bandwidth that passes "> 0" but divides by zero later);
- textual: the YAML text of a valid config with byte-level damage (non-UTF-8 bytes, lists and
  mappings as keys, deep nesting, digits runs, anchors, tags, cut-off text);
- way-points: arbitrary nested lists straight into ``Path.from_waypoints``.

Deterministic (``derandomize``), no deadline (a CI machine's speed is not what is tested).
"""

from __future__ import annotations

import copy
import math

import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from pf_offboard.config import parse_config_bytes
from pf_offboard.errors import ConfigError, InputError
from pf_offboard.path import Path

FUZZ = settings(max_examples=700, deadline=None, derandomize=True, suppress_health_check=list(HealthCheck))

BASE = {
    "path": {"frame": "enu", "closed": True, "moving_frame": "auto", "waypoints": [[0.0, 0.0, 1.0], [1.0, 0.0, 1.2], [1.0, 1.0, 1.0], [0.0, 1.0, 1.2]]},
    "speed_m_s": 0.5,
    "gains": {"transversal": {"bandwidth_hz": 2.0, "damping": 0.7}, "tangential": {"bandwidth_hz": 1.0, "damping": 0.8}},
    "yaw": {"mode": "table", "yaw_deg": 0.0, "table": [[0.0, 0.0], [1.0, 45.0]]},
    "limits": {"max_tilt_deg": 30.0, "min_thrust_m_s2": 2.0, "max_thrust_m_s2": 20.0, "max_approach_speed_m_s": 1.0, "max_tilt_rate_rad_s": 3.0},
    "flight": {"output_mode": "attitude", "setpoint_rate_hz": 50.0, "state_timeout_s": 0.5, "hover_thrust": 0.5,
               "takeoff_altitude_m": 2.0, "throw_activation_height_m": 2.0, "end_action": "hold", "attitude_time_constant_s": 0.1,
               "velocity_correction_s": 1.0},
    "vehicle": {},
}  # fmt: skip

WORDS = ["enu", "ned", "auto", "frenet", "rmf", "constant", "tangent", "table", "acceleration", "attitude", "rates", "hold", "land", ""]
scalars = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(min_value=-(10**6), max_value=10**6),
    st.integers(min_value=10**300, max_value=10**420),  # "1e400 written as digits"
    st.floats(allow_nan=True, allow_infinity=True),
    st.floats(min_value=0.0, max_value=1e-300),  # subnormals: pass "> 0", divide by zero later
    st.floats(min_value=-30.0, max_value=30.0),
    st.sampled_from(WORDS),
    st.text(max_size=8),
)
# one level of lists / mappings is enough to reach every type check (deeper nesting is the textual
# test's job) and keeps generation cheap
values = st.one_of(scalars, st.lists(scalars, max_size=4), st.dictionaries(st.text(max_size=5), scalars, max_size=3))

# dotted places in BASE a mutation can hit (sections, fields, way-points and their coordinates)
PLACES = [("path",), ("path", "waypoints"), ("path", "waypoints", 1), ("path", "waypoints", 2, 0), ("path", "closed"),
          ("path", "frame"), ("path", "moving_frame"), ("speed_m_s",), ("gains",), ("gains", "transversal"),
          ("gains", "transversal", "bandwidth_hz"), ("gains", "transversal", "damping"), ("gains", "tangential", "bandwidth_hz"),
          ("gains", "tangential", "damping"), ("yaw",), ("yaw", "mode"), ("yaw", "yaw_deg"), ("yaw", "table"), ("yaw", "table", 1),
          ("limits",), ("limits", "max_tilt_deg"), ("limits", "min_thrust_m_s2"), ("limits", "max_thrust_m_s2"),
          ("limits", "max_approach_speed_m_s"), ("limits", "max_tilt_rate_rad_s"), ("flight",), ("flight", "output_mode"),
          ("flight", "setpoint_rate_hz"), ("flight", "state_timeout_s"), ("flight", "hover_thrust"), ("flight", "takeoff_altitude_m"),
          ("flight", "end_action"), ("flight", "attitude_time_constant_s"), ("flight", "velocity_correction_s"), ("vehicle",), ("vehicle", "accel_gain_xy"),
          ("vehicle", "accel_lag_xy_s"), ("unknown_section",)]  # fmt: skip


def _set(doc: dict, place: tuple, value: object, delete: bool) -> None:
    node = doc
    for key in place[:-1]:
        if isinstance(node, dict) and key in node:
            node = node[key]
        elif isinstance(node, list) and isinstance(key, int) and key < len(node):
            node = node[key]
        else:
            return
    last = place[-1]
    if isinstance(node, dict):
        if delete:
            node.pop(last, None)
        else:
            node[last] = value
    elif isinstance(node, list) and isinstance(last, int) and last < len(node):
        node[last] = value


def _load(data: bytes) -> None:
    """Load a config and build what `sim` / `fly` build from it; only bad-input errors allowed."""
    try:
        config = parse_config_bytes(data, "fuzz.yaml")
    except ConfigError as exc:
        assert "\n" not in str(exc) and exc.field, f"not one line naming a field: {exc!r}"
        return
    # it loaded: the controller and the flight settings are built from it without surprises
    import argparse

    from pf_offboard.app.fly import flight_settings
    from pf_offboard.control import PathFollower

    try:
        PathFollower.from_config(config)
        flight_settings(config, argparse.Namespace(output=None, end_action=None))
    except InputError:
        pass


def _dump(doc: object) -> bytes:
    dumper = getattr(yaml, "CSafeDumper", yaml.SafeDumper)
    return yaml.dump(doc, Dumper=dumper, allow_unicode=True, sort_keys=False).encode("utf-8")


@FUZZ
@given(st.lists(st.tuples(st.sampled_from(PLACES), values, st.booleans()), min_size=1, max_size=4))
def test_structured_config_fuzz_raises_only_config_errors(mutations) -> None:
    doc = copy.deepcopy(BASE)
    for place, value, delete in mutations:
        _set(doc, place, value, delete and len(place) > 1)
    try:
        data = _dump(doc)
    except (yaml.YAMLError, RecursionError):
        return  # not representable as YAML: not a file a user could write
    _load(data)


BASE_TEXT = _dump(BASE)
# fragments a hand-edited or damaged file contains
SNIPPETS = [b"\xff\xfe", b"\xc3\x28", b"\x00", b"? [a, b]\n: 1\n", b"{[1]: 2}", b"? {a: 1}\n: 2\n", b"[" * 3000, b"{a: " * 2000,
            b"9" * 500, b"9" * 5000, b"1e-320", b"-.inf", b".nan", b"&a [1, *a]", b"*missing", b"!!binary ZZZ", b"!!timestamp x",
            b"!!python/object:os.system x", b"<<: {a: 1}", b"\t", b":", b"- ", b"\n  - [1, 2, 3]\n", b"'", b'"\\x', b"%YAML 9.9\n---\n"]  # fmt: skip


@FUZZ
@given(st.lists(st.tuples(st.integers(0, len(BASE_TEXT)), st.integers(0, 40), st.one_of(st.sampled_from(SNIPPETS), st.binary(max_size=12))), min_size=1, max_size=4))
def test_damaged_config_text_raises_only_config_errors(edits) -> None:
    data = bytearray(BASE_TEXT)
    for at, cut, insert in edits:
        at = min(at, len(data))
        data[at : at + cut] = insert
    _load(bytes(data))


coordinate = st.one_of(
    st.floats(min_value=-20.0, max_value=20.0),
    st.floats(allow_nan=True, allow_infinity=True),
    st.integers(min_value=-30, max_value=30),
    st.integers(min_value=10**300, max_value=10**400),
    st.sampled_from(["1", "x", None, True]),
)


@settings(FUZZ, max_examples=500)
@given(
    st.one_of(st.lists(st.lists(coordinate, min_size=2, max_size=4), max_size=6), st.lists(coordinate, max_size=4), scalars),
    st.one_of(st.booleans(), st.sampled_from([0, 1, "yes", None])),
    st.sampled_from(["auto", "frenet", "rmf", "bishop"]),
)
def test_waypoint_parser_raises_only_input_errors(points, closed, frame) -> None:
    try:
        path = Path.from_waypoints(points, closed=closed, frame=frame)
    except InputError as exc:
        assert "\n" not in str(exc) and exc.field
        return
    assert math.isfinite(path.length_m) and path.length_m > 0
