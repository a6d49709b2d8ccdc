"""Paths from planning tools: way-points in latitude / longitude / altitude, read from

- a QGroundControl ``.plan`` (JSON; ``mission.items``: NAV_WAYPOINT items, ``params[4..6]`` =
  lat, lon, alt; item ``frame`` 3 = altitude relative to home, 0 = AMSL);
- a Mission Planner / QGroundControl ``.waypoints`` file (``QGC WPL 110`` text; line 0 after the
  header is the home position and is not a way-point);
- a ``.csv`` with a header naming the ``lat``, ``lon`` and ``alt`` columns;
- a GeoJSON ``LineString`` (``.geojson`` / ``.json``; coordinates are ``[lon, lat, alt]``);
- a KML ``LineString`` (``.kml``; ``<coordinates>`` are ``lon,lat,alt``),

and converted to the vehicle's local ENU frame (the frame of its EKF origin) with the WGS-84
routines of :mod:`pf_offboard.geo`. Every problem in a file is one :class:`PathFileError` naming
the file, the item or line, and the reason (``pf-offboard`` prints it on one line, exit 2).

Altitude references are never guessed: the config says ``altitude_reference: relative_home`` or
``amsl``; where a file records its own (``.plan`` / ``.waypoints`` frames, KML ``altitudeMode``
``absolute``) the two must agree.
"""

from __future__ import annotations

import csv
import io
import json
import math
import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from pf_offboard.errors import InputError
from pf_offboard.geo import GeoPoint, geodetic_to_enu

ALTITUDE_REFERENCES = ("relative_home", "amsl")
SUFFIXES = (".plan", ".waypoints", ".csv", ".geojson", ".json", ".kml")
# A geodetic path whose local way-points are farther than this from the origin is refused (a wrong
# origin or a swapped lat/lon is kilometres off), whatever the safety: fence (checked as well).
MAX_DISTANCE_FROM_ORIGIN_M = 1000.0

MAV_CMD_NAV_WAYPOINT = 16
MAV_FRAME_GLOBAL = 0  # altitude AMSL
MAV_FRAME_GLOBAL_RELATIVE_ALT = 3  # altitude relative to home
MAV_FRAME_GLOBAL_INT = 5
MAV_FRAME_GLOBAL_RELATIVE_ALT_INT = 6
_FRAME_REFERENCE = {
    MAV_FRAME_GLOBAL: "amsl",
    MAV_FRAME_GLOBAL_INT: "amsl",
    MAV_FRAME_GLOBAL_RELATIVE_ALT: "relative_home",
    MAV_FRAME_GLOBAL_RELATIVE_ALT_INT: "relative_home",
}
MAV_CMD_NAV_TAKEOFF = 22
_RELATIVE_FRAMES = (MAV_FRAME_GLOBAL_RELATIVE_ALT, MAV_FRAME_GLOBAL_RELATIVE_ALT_INT)
_TERRAIN_FRAMES = (10, 11)  # MAV_FRAME_GLOBAL_TERRAIN_ALT(_INT)


def command_name(command: int) -> str:
    """A MAV_CMD's name from pymavlink's enums ("NAV_TAKEOFF"), or "command N" if unknown."""
    from pymavlink.dialects.v20 import common

    entry = common.enums["MAV_CMD"].get(command)
    return entry.name.removeprefix("MAV_CMD_") if entry is not None else f"command {command}"


def frame_name(frame: int) -> str:
    """A MAV_FRAME's name from pymavlink's enums ("GLOBAL_TERRAIN_ALT"), or "frame N" if unknown."""
    from pymavlink.dialects.v20 import common

    entry = common.enums["MAV_FRAME"].get(frame)
    return entry.name.removeprefix("MAV_FRAME_") if entry is not None else f"frame {frame}"
# Mission commands that are not a place to fly through: skipped and reported (DO_*, CONDITION_*),
# and take-off / land / return (the app takes off itself with --takeoff and hands back at the end).
_NON_POSITIONAL = set(range(112, 160)) | set(range(176, 253)) | set(range(3000, 3100)) | {20, 21, 22}


class PathFileError(InputError):
    """A way-point file is unreadable or wrong: ``field`` is ``FILE: item N`` / ``FILE: line N``."""

    def __init__(self, source: str, where: str, reason: str) -> None:
        super().__init__(f"{source}: {where}" if where else source, reason)


@dataclass(frozen=True)
class GeoWaypoint:
    """One way-point as the file gives it: WGS-84 degrees and altitude (m, reference in ``GeoPath``)."""

    lat_deg: float
    lon_deg: float
    alt_m: float
    where: str  # "item 3" / "line 5": for error messages


@dataclass(frozen=True)
class GeoPath:
    """Way-points read from a planning tool's file.

    ``altitude_reference``: what the file itself records (``relative_home`` | ``amsl``), or None
    when the format does not say (CSV, GeoJSON, KML without ``absolute``). ``skipped``: the items
    that are not way-points (take-off, speed changes, ...), named, for the user's information.
    """

    source: str
    file_format: str
    waypoints: tuple[GeoWaypoint, ...]
    altitude_reference: str | None
    skipped: tuple[str, ...] = ()
    takeoff_alt_m: float | None = None  # the plan's take-off altitude above home (m), when it has one

    def lat_lon_alt(self) -> np.ndarray:
        """(N, 3) [lat_deg, lon_deg, alt_m] as in the file."""
        return np.array([[w.lat_deg, w.lon_deg, w.alt_m] for w in self.waypoints], dtype=float)


# ------------------------------------------------------------------------------------- reading
MAX_PATH_FILE_BYTES = 16 << 20  # a way-point file of a few thousand points is well below this


def read_geopath(path: str | os.PathLike[str]) -> GeoPath:
    """Read a ``.plan`` / ``.waypoints`` / ``.csv`` / ``.geojson`` / ``.json`` / ``.kml`` file."""
    p = Path(path)
    source = str(p)
    suffix = p.suffix.lower()
    if suffix not in SUFFIXES:
        raise PathFileError(source, "", f"unknown way-point file type {suffix or '(none)'!r} (use one of {', '.join(SUFFIXES)})")
    from pf_offboard.inputfile import read_bounded

    try:
        text = read_bounded(p, MAX_PATH_FILE_BYTES).decode("utf-8-sig")
    except ValueError as exc:
        if isinstance(exc, UnicodeDecodeError):
            raise PathFileError(source, "", f"not UTF-8 text ({exc.reason} at byte {exc.start})") from None
        raise PathFileError(source if len(source) <= 200 else source[:100] + "..." + source[-100:], "", str(exc)) from None
    except UnicodeDecodeError as exc:
        raise PathFileError(source, "", f"not UTF-8 text ({exc.reason} at byte {exc.start})") from None
    if suffix == ".plan":
        geo = parse_plan(text, source)
    elif suffix == ".waypoints":
        geo = parse_waypoints(text, source)
    elif suffix == ".csv":
        geo = parse_csv(text, source)
    elif suffix == ".kml":
        geo = parse_kml(text, source)
    else:
        geo = parse_geojson(text, source)
    if len(geo.waypoints) < 2:
        raise PathFileError(source, "", f"{len(geo.waypoints)} way-point(s) found; a path needs at least 2")
    return geo


def _coordinate(value: object, source: str, where: str, name: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise PathFileError(source, where, f"{name} must be a number, got {value!r}")
    v = float(value)
    if not math.isfinite(v):
        raise PathFileError(source, where, f"{name} must be finite, got {v}")
    return v


def _waypoint(lat: object, lon: object, alt: object, source: str, where: str) -> GeoWaypoint:
    la = _coordinate(lat, source, where, "latitude")
    lo = _coordinate(lon, source, where, "longitude")
    al = _coordinate(alt, source, where, "altitude")
    if not -90.0 <= la <= 90.0:
        raise PathFileError(source, where, f"latitude {la:g} deg is outside [-90, 90] (latitude and longitude swapped?)")
    if not -180.0 <= lo <= 180.0:
        raise PathFileError(source, where, f"longitude {lo:g} deg is outside [-180, 180]")
    if la == 0.0 and lo == 0.0:
        raise PathFileError(source, where, "latitude and longitude are both 0 (an unset position)")
    if not -1000.0 <= al <= 20000.0:
        raise PathFileError(source, where, f"altitude {al:g} m is not plausible")
    return GeoWaypoint(la, lo, al, where)


def _frame_reference(frame: object, source: str, where: str) -> str:
    if isinstance(frame, bool) or not isinstance(frame, int):
        raise PathFileError(source, where, f"frame must be an integer, got {frame!r}")
    if frame not in _FRAME_REFERENCE:
        name = f"terrain-relative frame {frame} ({frame_name(frame)})" if frame in _TERRAIN_FRAMES else f"frame {frame} ({frame_name(frame)})"
        raise PathFileError(source, where, f"{name} is not supported: use altitudes relative to home (frame 3) or AMSL (frame 0)")
    return _FRAME_REFERENCE[frame]


def _one_reference(refs: Sequence[tuple[str, str]], source: str) -> str | None:
    """All way-points must share one altitude reference; the first that differs is named."""
    if not refs:
        return None
    first = refs[0][1]
    for where, ref in refs[1:]:
        if ref != first:
            raise PathFileError(source, where, f"altitude reference {ref} differs from the first way-point's ({first}); use one for all")
    return first


def _load_json(text: str, source: str) -> object:
    """JSON text, or one PathFileError: syntax, integers too long to read, nesting too deep."""
    try:
        return json.loads(text)
    except json.JSONDecodeError as exc:
        raise PathFileError(source, f"line {exc.lineno}", f"not valid JSON: {exc.msg}") from None
    except ValueError as exc:  # an integer of more than 4300 digits (Python's int limit)
        raise PathFileError(source, "", f"unreadable JSON value: {str(exc).split(';')[0]}") from None
    except RecursionError:
        raise PathFileError(source, "", "JSON nested too deeply (a way-point file is a few levels deep)") from None


def parse_plan(text: str, source: str = "<plan>") -> GeoPath:
    """A QGroundControl ``.plan``: the NAV_WAYPOINT items of ``mission.items``, in order."""
    data = _load_json(text, source)
    if not isinstance(data, dict) or data.get("fileType") != "Plan":
        raise PathFileError(source, "", 'not a QGroundControl plan (no "fileType": "Plan")')
    mission = data.get("mission")
    items = mission.get("items") if isinstance(mission, dict) else None
    if not isinstance(items, list):
        raise PathFileError(source, "mission", 'no "items" list')
    waypoints: list[GeoWaypoint] = []
    refs: list[tuple[str, str]] = []
    skipped: list[str] = []
    takeoff_alt_m: float | None = None
    for i, item in enumerate(items):
        where = f"item {i}"
        if not isinstance(item, dict):
            raise PathFileError(source, where, "not a JSON object")
        kind = item.get("type")
        if kind == "ComplexItem":
            raise PathFileError(source, where, f"complex item ({item.get('complexItemType', '?')}) is not supported: "
                                "convert it to way-points in QGroundControl first")  # fmt: skip
        if kind != "SimpleItem":
            raise PathFileError(source, where, f"unknown item type {kind!r}")
        command = item.get("command")
        if isinstance(command, bool) or not isinstance(command, int):
            raise PathFileError(source, where, f"command must be an integer, got {command!r}")
        if command != MAV_CMD_NAV_WAYPOINT:
            params = item.get("params")
            if (command == MAV_CMD_NAV_TAKEOFF and takeoff_alt_m is None and item.get("frame") in _RELATIVE_FRAMES
                    and isinstance(params, list) and len(params) == 7):
                takeoff_alt_m = _coordinate(params[6], source, where, "take-off altitude")
            if command in _NON_POSITIONAL:
                skipped.append(f"{where} ({command_name(command)})")
                continue
            raise PathFileError(source, where, f"mission command {command_name(command)} ({command}) is not a way-point (MAV_CMD_NAV_WAYPOINT, 16): "
                                "remove take-off / land / loiter / return items, the app flies way-points only")  # fmt: skip
        params = item.get("params")
        if not isinstance(params, list) or len(params) != 7:
            raise PathFileError(source, where, "params must be a list of 7 numbers")
        refs.append((where, _frame_reference(item.get("frame"), source, where)))
        waypoints.append(_waypoint(params[4], params[5], params[6], source, where))
    return GeoPath(source, "plan", tuple(waypoints), _one_reference(refs, source), tuple(skipped), takeoff_alt_m)


def parse_waypoints(text: str, source: str = "<waypoints>") -> GeoPath:
    """A Mission Planner / QGroundControl way-point file, ``QGC WPL 110`` or the older ``QGC WPL
    100``, read with pymavlink's :class:`~pymavlink.mavwp.MAVWPLoader`. The first entry is home,
    not a way-point. Problems the loader would report without a line number (a wrong field
    count, a field that is not a number) are named by line first."""
    import tempfile

    from pymavlink import mavwp

    lines = text.splitlines()
    header = lines[0].strip() if lines else ""
    fields_per_line = {"QGC WPL 110": 12, "QGC WPL 100": 13}.get(header)
    if fields_per_line is None:
        raise PathFileError(source, "line 1", "not a QGC WPL 110 (or 100) way-point file (first line must be 'QGC WPL 110')")
    entry_lines: list[int] = []
    for n, line in enumerate(lines[1:], start=2):
        if not line.strip() or line.startswith("#"):
            continue
        fields = line.split()
        if len(fields) != fields_per_line:
            layout = "INDEX CURRENT FRAME COMMAND P1..P4 LAT LON ALT AUTOCONTINUE" if fields_per_line == 12 else "the 13 fields of WPL 100"
            raise PathFileError(source, f"line {n}", f"expected {fields_per_line} fields ({layout}), got {len(fields)}")
        try:
            [float(f) for f in fields]
        except ValueError:
            raise PathFileError(source, f"line {n}", "every field must be a number") from None
        entry_lines.append(n)
    loader = mavwp.MAVWPLoader()
    with tempfile.TemporaryDirectory() as tmp:  # the loader reads a file by name
        copy = Path(tmp) / "mission.waypoints"
        copy.write_text(text, encoding="utf-8")
        try:
            loader.load(str(copy))
        except (mavwp.MAVWPError, ValueError) as exc:
            raise PathFileError(source, "", f"pymavlink cannot read it: {exc}") from None
    items = [loader.wp(i) for i in range(loader.count())]
    waypoints: list[GeoWaypoint] = []
    refs: list[tuple[str, str]] = []
    skipped: list[str] = []
    takeoff_alt_m: float | None = None
    for k, (item, n) in enumerate(zip(items, entry_lines)):
        where = f"line {n}"
        if k == 0:
            if item.seq != 0:
                raise PathFileError(source, where, f"the first entry must be the home position (index 0), got index {item.seq}")
            continue  # home: where the vehicle was when the plan was made, not a place to fly through
        command = int(item.command)
        if command != MAV_CMD_NAV_WAYPOINT:
            if command == MAV_CMD_NAV_TAKEOFF and item.frame in _RELATIVE_FRAMES and takeoff_alt_m is None:
                takeoff_alt_m = float(item.z)
            if command in _NON_POSITIONAL:
                skipped.append(f"{where} ({command_name(command)})")
                continue
            raise PathFileError(source, where, f"mission command {command_name(command)} is not a way-point (MAV_CMD_NAV_WAYPOINT, 16)")
        refs.append((where, _frame_reference(int(item.frame), source, where)))
        waypoints.append(_waypoint(item.x, item.y, item.z, source, where))
    return GeoPath(source, "waypoints", tuple(waypoints), _one_reference(refs, source), tuple(skipped), takeoff_alt_m)


_CSV_NAMES = {
    "lat": ("lat", "latitude", "lat_deg"),
    "lon": ("lon", "lng", "long", "longitude", "lon_deg"),
    "alt": ("alt", "altitude", "alt_m", "height", "alt_amsl_m", "alt_rel_m"),
}


def parse_csv(text: str, source: str = "<csv>") -> GeoPath:
    """A CSV with a header row naming ``lat``, ``lon`` and ``alt`` columns (degrees, degrees, m);
    other columns are ignored, ``#`` lines are comments."""
    rows = [(n, line) for n, line in enumerate(text.splitlines(), start=1) if line.strip() and not line.lstrip().startswith("#")]
    if not rows:
        raise PathFileError(source, "", "empty file")
    header_line, header = rows[0]
    names = [h.strip().lower() for h in next(csv.reader(io.StringIO(header)))]
    columns: dict[str, int] = {}
    for key, aliases in _CSV_NAMES.items():
        found = [i for i, h in enumerate(names) if h in aliases]
        if not found:
            raise PathFileError(source, f"line {header_line}", f"header has no {key} column (one of {', '.join(aliases)}; got {', '.join(names)})")
        if len(found) > 1:
            raise PathFileError(source, f"line {header_line}", f"header has {len(found)} {key} columns")
        columns[key] = found[0]
    waypoints = []
    for n, line in rows[1:]:
        where = f"line {n}"
        fields = next(csv.reader(io.StringIO(line)))
        if len(fields) != len(names):
            raise PathFileError(source, where, f"{len(fields)} fields, the header has {len(names)}")
        values = []
        for key in ("lat", "lon", "alt"):
            raw = fields[columns[key]].strip()
            try:
                values.append(float(raw))
            except ValueError:
                raise PathFileError(source, where, f"{key} {raw!r} is not a number") from None
        waypoints.append(_waypoint(*values, source, where))
    return GeoPath(source, "csv", tuple(waypoints), None)


def parse_geojson(text: str, source: str = "<geojson>") -> GeoPath:
    """A GeoJSON ``LineString`` (bare, in a ``Feature``, or the one LineString of a ``FeatureCollection``);
    every position needs its altitude: ``[lon, lat, alt]``."""
    data = _load_json(text, source)
    lines: list[tuple[str, object]] = []

    def visit(obj: object, where: str) -> None:
        if not isinstance(obj, dict):
            raise PathFileError(source, where, "not a GeoJSON object")
        kind = obj.get("type")
        if kind == "FeatureCollection":
            feats = obj.get("features")
            if not isinstance(feats, list):
                raise PathFileError(source, where, 'FeatureCollection without a "features" list')
            for i, f in enumerate(feats):
                visit(f, f"feature {i}")
        elif kind == "Feature":
            visit(obj.get("geometry"), where)
        elif kind == "LineString":
            lines.append((where, obj.get("coordinates")))
        elif kind in ("Point", "MultiPoint", "Polygon", "MultiLineString", "MultiPolygon", "GeometryCollection"):
            return  # markers, areas: not the path
        else:
            raise PathFileError(source, where, f"unknown GeoJSON type {kind!r}")

    visit(data, "top level")
    if len(lines) != 1:
        raise PathFileError(source, "", f"{len(lines)} LineStrings found; the file must hold exactly one (the path)")
    where0, coords = lines[0]
    if not isinstance(coords, list):
        raise PathFileError(source, where0, "LineString coordinates must be a list")
    waypoints = []
    for i, c in enumerate(coords):
        where = f"{where0}, position {i}" if where0 != "top level" else f"position {i}"
        if not isinstance(c, list) or len(c) < 2:
            raise PathFileError(source, where, f"must be [lon, lat, alt], got {c!r}")
        if len(c) < 3:
            raise PathFileError(source, where, "has no altitude: positions must be [lon, lat, alt]")
        waypoints.append(_waypoint(c[1], c[0], c[2], source, where))
    return GeoPath(source, "geojson", tuple(waypoints), None)


def parse_kml(text: str, source: str = "<kml>") -> GeoPath:
    """A KML file with exactly one ``LineString``: ``<coordinates>lon,lat,alt ...</coordinates>``.
    ``altitudeMode`` ``absolute`` records AMSL; other modes leave the reference to the config."""
    import xml.etree.ElementTree as ET

    try:
        root = ET.fromstring(text)
    except ET.ParseError as exc:
        line = exc.position[0] if exc.position else 0
        raise PathFileError(source, f"line {line}", f"not valid XML: {exc}") from None
    strings = [e for e in root.iter() if e.tag.rsplit("}", 1)[-1] == "LineString"]
    if len(strings) != 1:
        raise PathFileError(source, "", f"{len(strings)} LineStrings found; the file must hold exactly one (the path)")
    ls = strings[0]
    coords = next((e for e in ls if e.tag.rsplit("}", 1)[-1] == "coordinates"), None)
    mode = next((e.text or "" for e in ls if e.tag.rsplit("}", 1)[-1] == "altitudeMode"), "").strip()
    if coords is None or not (coords.text or "").strip():
        raise PathFileError(source, "LineString", "no <coordinates>")
    waypoints = []
    for i, tuple_text in enumerate((coords.text or "").split()):
        where = f"coordinate {i}"
        parts = tuple_text.split(",")
        if len(parts) != 3:
            raise PathFileError(source, where, f"must be lon,lat,alt, got {tuple_text!r}")
        try:
            lon, lat, alt = (float(v) for v in parts)
        except ValueError:
            raise PathFileError(source, where, f"must be three numbers lon,lat,alt, got {tuple_text!r}") from None
        waypoints.append(_waypoint(lat, lon, alt, source, where))
    return GeoPath(source, "kml", tuple(waypoints), "amsl" if mode == "absolute" else None)


# ------------------------------------------------------------------------------------- to local
def check_distance_from_origin(points_enu_m: np.ndarray, source: str, limit_m: float = MAX_DISTANCE_FROM_ORIGIN_M,
                               names: Sequence[str] | None = None) -> None:  # fmt: skip
    """Refuse local way-points (ENU m) farther than ``limit_m`` from the origin: a wrong origin,
    swapped coordinates or a plan for another field. The one bound a geodetic path must pass
    before any traffic; the ``safety:`` geofence, when configured, is checked as well."""
    d = np.linalg.norm(np.asarray(points_enu_m, dtype=float), axis=1)
    worst = int(np.argmax(d))
    if d[worst] > limit_m:
        where = names[worst] if names is not None else f"way-point {worst}"
        raise PathFileError(source, where, f"is {d[worst]:.0f} m from the vehicle's origin (more than {limit_m:g} m): "
                            "wrong field, wrong origin or swapped latitude/longitude? refused")  # fmt: skip


def to_local(geo: GeoPath, altitude_reference: str, origin: GeoPoint, home_alt_amsl_m: float | None = None) -> np.ndarray:
    """Local ENU way-points (N, 3, m) in the frame of ``origin`` (the EKF origin).

    ``altitude_reference``: ``relative_home`` (altitudes above the home position, whose AMSL
    altitude is ``home_alt_amsl_m``, default the origin's) or ``amsl``. Refuses a file whose own
    reference disagrees, and way-points beyond :data:`MAX_DISTANCE_FROM_ORIGIN_M`."""
    if altitude_reference not in ALTITUDE_REFERENCES:
        raise InputError("path.altitude_reference", f"must be one of {', '.join(ALTITUDE_REFERENCES)}, got {altitude_reference!r}")
    if geo.altitude_reference is not None and geo.altitude_reference != altitude_reference:
        raise InputError("path.altitude_reference", f"is {altitude_reference}, but {geo.source} gives its altitudes as "
                         f"{geo.altitude_reference}; make them agree")  # fmt: skip
    lla = geo.lat_lon_alt()
    if altitude_reference == "relative_home":
        lla[:, 2] += origin.alt_amsl_m if home_alt_amsl_m is None else home_alt_amsl_m
    local = geodetic_to_enu(lla, origin)
    check_distance_from_origin(local, geo.source, names=[w.where for w in geo.waypoints])
    return local
