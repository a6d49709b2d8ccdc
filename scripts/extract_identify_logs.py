#!/usr/bin/env python3
"""Trim the recorded real-PX4 flights into the small extracts tests/identify/ uses.

The recorded flights (``pf-offboard fly`` against a real PX4 SIH quad, see
shared/data/px4-sih/README.md) are 0.8-1.5 MB each, mostly telemetry identify does not read. This
keeps, from 2 s before the first flying setpoint to the end, only the records ``identify`` uses —
LOCAL_POSITION_NED, ATTITUDE_QUATERNION (the vertical fit's measured tilt; a rates flight's thrust
acts along it too), the autopilot's HEARTBEAT and PARAM_VALUE (in) and the
app's setpoints (out: SET_POSITION_TARGET_LOCAL_NED, SET_ATTITUDE_TARGET) — byte for byte with
their original UNIX stamps, and writes them as deterministic ``.tlog.gz`` (gzip mtime 0):

    python scripts/extract_identify_logs.py [SRC_DIR] [OUT_DIR]
    python scripts/extract_identify_logs.py --one SRC.tlog DST.tlog.gz

The second form trims one log, e.g. the ``identify --connect`` excitation flights against the real
PX4 SIH in tests/data/identify/px4-sih-excitation-*.tlog.gz (their full logs are not kept here).
SRC_DIR defaults to ../shared/data/px4-sih (beside the repository), OUT_DIR to tests/data/identify.
Running it twice gives identical bytes.
"""

from __future__ import annotations

import gzip
import io
import struct
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from pf_offboard.logs.tlog import iter_tlog  # noqa: E402

FLIGHTS = ("accel-1.5hz", "attitude-1.5hz", "rates-1.5hz-tau0.2")
KEEP_IN = {"LOCAL_POSITION_NED", "ATTITUDE_QUATERNION", "HEARTBEAT", "PARAM_VALUE"}
KEEP_OUT = {"SET_POSITION_TARGET_LOCAL_NED", "SET_ATTITUDE_TARGET"}
LEAD_S = 2.0


def _flying(msg) -> bool:
    """An acceleration or attitude setpoint (not a take-off position setpoint)."""
    if msg.get_type() == "SET_ATTITUDE_TARGET":
        return True
    return msg.type_mask & 0x007 == 0x007 and not msg.type_mask & 0x1C0


def extract(src: Path, dst: Path) -> int:
    entries = list(iter_tlog(src))
    start = next(e.time_unix_s for e in entries if e.direction == "out" and e.message.get_type() in KEEP_OUT and _flying(e.message))
    buf = io.BytesIO()
    for e in entries:
        keep = e.message.get_type() in (KEEP_OUT if e.direction == "out" else KEEP_IN)
        # PARAM_VALUE (the hover thrust) is answered before the flight: keep it whenever it came
        if keep and (e.time_unix_s >= start - LEAD_S or e.message.get_type() == "PARAM_VALUE"):
            buf.write(struct.pack(">Q", int(round(e.time_unix_s * 1e6))) + e.frame)
    data = gzip.compress(buf.getvalue(), compresslevel=9, mtime=0)
    dst.write_bytes(data)
    return len(data)


def main(argv: list[str]) -> int:
    if argv[:1] == ["--one"]:  # one log: --one SRC.tlog[.gz] DST.tlog.gz (e.g. an identify --connect flight)
        size = extract(Path(argv[1]), Path(argv[2]))
        print(f"{argv[2]}: {size / 1024:.0f} KiB")
        return 0
    src_dir = Path(argv[0]) if argv else ROOT.parent / "shared" / "data" / "px4-sih"
    out_dir = Path(argv[1]) if len(argv) > 1 else ROOT / "tests" / "data" / "identify"
    out_dir.mkdir(parents=True, exist_ok=True)
    for name in FLIGHTS:
        size = extract(src_dir / f"{name}.tlog.gz", out_dir / f"px4-sih-{name}.tlog.gz")
        print(f"{out_dir / f'px4-sih-{name}.tlog.gz'}: {size / 1024:.0f} KiB")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
