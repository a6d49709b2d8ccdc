"""Path-file fuzzing: damaged way-point files of every format (.plan, .waypoints, .csv, .geojson,
.kml) — bytes flipped, cut, repeated, numbers replaced by NaN / 1e400 / huge integers, nesting —
read as a file and through a config. Each is either a path of finite way-points or one
PathFileError / ConfigError line naming the file; never another exception, never a hang."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from pf_offboard.config import load_config
from pf_offboard.errors import InputError
from pf_offboard.geopath import read_geopath

DATA = Path(__file__).resolve().parent / "data" / "geo"
SAMPLES = {suffix: (DATA / f"mission{suffix}").read_bytes() for suffix in (".plan", ".waypoints", ".csv", ".geojson", ".kml")}
FUZZ = settings(max_examples=1100, deadline=None, derandomize=True, suppress_health_check=list(HealthCheck))
NASTY = [b"nan", b"NaN", b"inf", b"-1e400", b"1e400", b"9" * 5000, b"", b"\x00", b"\xff\xfe", b"[[[[[[[[[[" * 200, b"{", b"\"",
         b"<coordinates>", b"\n", b",", b"-", b"1e-320", b"null", b"true", b"\t\t\t"]  # fmt: skip


@st.composite
def damaged(draw) -> tuple[str, bytes]:
    suffix = draw(st.sampled_from(sorted(SAMPLES)))
    data = bytearray(SAMPLES[suffix])
    for _ in range(draw(st.integers(1, 4))):
        kind = draw(st.sampled_from(["flip", "cut", "insert", "replace_number", "repeat"]))
        if not data:
            break
        i = draw(st.integers(0, len(data) - 1))
        if kind == "flip":
            data[i] = draw(st.integers(0, 255))
        elif kind == "cut":
            j = draw(st.integers(i, min(len(data), i + 200)))
            del data[i:j]
        elif kind == "insert":
            data[i:i] = draw(st.sampled_from(NASTY))
        elif kind == "replace_number":
            j = i
            while j < len(data) and (chr(data[j]).isdigit() or data[j] in b".-"):
                j += 1
            data[i:j] = draw(st.sampled_from(NASTY))
        else:
            j = draw(st.integers(i, min(len(data), i + 100)))
            data[i:i] = data[i:j] * draw(st.integers(2, 50))
    return suffix, bytes(data)


@FUZZ
@given(case=damaged())
def test_damaged_path_files_are_a_path_or_one_error_line(case, tmp_path_factory) -> None:
    suffix, data = case
    d = tmp_path_factory.mktemp("pf", numbered=True)
    path = d / f"mission{suffix}"
    path.write_bytes(data)
    try:
        geo = read_geopath(path)
    except InputError as exc:
        text = str(exc)
        assert "\n" not in text and str(path) in text, text
    else:
        pts = np.array([(w.lat_deg, w.lon_deg, w.alt_m) for w in geo.waypoints], dtype=float)
        assert pts.size and np.all(np.isfinite(pts)), pts
    # and through a config (as `fly` / `sim` read it): a config error naming the file, or a config
    config = d / "c.yaml"
    config.write_text(f"path:\n  file: {path.name}\n  altitude_reference: relative_home\n  origin: [-35.363261, 149.165230, 584.0]\nspeed_m_s: 1.0\n")
    try:
        loaded = load_config(config)
    except InputError as exc:
        assert "\n" not in str(exc)
    else:
        assert all(math.isfinite(v) for p in loaded.path.waypoints_enu_m for v in p)
