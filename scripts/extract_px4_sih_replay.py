#!/usr/bin/env python3
"""Extract the replay windows of tests/data/px4_sih/ from the recorded real-PX4 SIH flights.

The flights (``../shared/data/px4-sih/*.tlog.gz`` beside the repository, or ``--source DIR``) are
``pf-offboard fly`` runs against a real PX4 SITL (SIH quad): every frame the app sent (component
191: the setpoints) and received (component 1: LOCAL_POSITION_NED and ATTITUDE_QUATERNION at
100 Hz, HIGHRES_IMU at 50 Hz). tests/sitl_mock/dynamics/test_dyn_px4_sih_replay.py replays the
setpoints of each window into the ``px4-sih`` preset, starting from the recorded state, and
compares the response. This script keeps only those windows (< 1 MB in all), so the test does not
depend on paths outside the repository:

    python scripts/extract_px4_sih_replay.py [--source DIR]

Time base: the vehicle's clock (time_boot_ms). A setpoint is stamped with the vehicle time of the
last telemetry frame received before it in the log (the app computes a setpoint from the latest
state); the log's wall-clock stamps jitter by ±0.2 s and are not used. Deterministic output.
"""

from __future__ import annotations

import argparse
import gzip
import io
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_SOURCE = ROOT.parent / "shared" / "data" / "px4-sih"
OUT = ROOT / "tests" / "data" / "px4_sih"
FLIGHTS = ("accel-1.5hz", "attitude-1.5hz", "rates-1.5hz-tau0.2")
WINDOW_S = 2.0
WINDOWS_PER_FLIGHT = 8
MARGIN_S = 0.3  # data kept before/after each window (setpoint latency, interpolation)
SETPOINT_KIND = {"SET_POSITION_TARGET_LOCAL_NED": 0, "SET_ATTITUDE_TARGET": 1}
ACCEL_ONLY_MASK = 0x3F  # position and velocity ignored: the app's acceleration output


def read_tlog(path: Path) -> dict[str, np.ndarray]:
    """Setpoints and telemetry of one .tlog.gz as arrays (vehicle time, s)."""
    from pymavlink import mavutil

    with tempfile.NamedTemporaryFile(suffix=".tlog") as tmp:
        tmp.write(gzip.decompress(path.read_bytes()))
        tmp.flush()
        log = mavutil.mavlink_connection(tmp.name, dialect="common")
        last_t = 0.0
        sp: list[tuple[float, ...]] = []
        att: list[tuple[float, ...]] = []
        vel: list[tuple[float, ...]] = []
        imu: list[tuple[float, ...]] = []
        while (msg := log.recv_match()) is not None:
            kind = msg.get_type()
            src = (msg.get_srcSystem(), msg.get_srcComponent())
            if src == (1, 1):
                if kind == "HIGHRES_IMU":
                    last_t = msg.time_usec * 1e-6
                    imu.append((last_t, msg.xacc, msg.yacc, msg.zacc))
                elif getattr(msg, "time_boot_ms", 0) > 0:
                    last_t = msg.time_boot_ms * 1e-3
                if kind == "ATTITUDE_QUATERNION":
                    att.append((last_t, msg.q1, msg.q2, msg.q3, msg.q4, msg.rollspeed, msg.pitchspeed, msg.yawspeed))
                elif kind == "LOCAL_POSITION_NED":
                    vel.append((last_t, msg.z, msg.vx, msg.vy, msg.vz))
            elif src == (1, 191) and kind in SETPOINT_KIND:
                # Columns: t, kind, type_mask, then accel NED (3) + yaw, or q (4) + thrust + body rates (3).
                if kind == "SET_POSITION_TARGET_LOCAL_NED":
                    values = (msg.afx, msg.afy, msg.afz, msg.yaw, 0.0, 0.0, 0.0, 0.0)
                else:
                    values = (*msg.q, msg.thrust, msg.body_roll_rate, msg.body_pitch_rate, msg.body_yaw_rate)
                sp.append((last_t, SETPOINT_KIND[kind], msg.type_mask, *values))
    return {"sp": np.array(sp), "att": np.array(att), "vel": np.array(vel), "imu": np.array(imu)}


def windows(data: dict[str, np.ndarray]) -> list[float]:
    """Start times of the windows: the flight's own output mode, airborne (> 0.8 m), evenly spread."""
    sp = data["sp"]
    output_kind = int(sp[-1, 1])
    usable = sp[:, 1] == output_kind
    if output_kind == 0:
        usable &= sp[:, 2].astype(int) == ACCEL_ONLY_MASK
    t_use = sp[usable, 0]
    starts = np.arange(t_use[0] + 3.0, t_use[-1] - WINDOW_S - MARGIN_S, WINDOW_S)
    vel = data["vel"]
    airborne = [t for t in starts if vel[np.searchsorted(vel[:, 0], t), 1] < -0.8]
    pick = np.linspace(0, len(airborne) - 1, min(WINDOWS_PER_FLIGHT, len(airborne))).round().astype(int)
    return [float(airborne[i]) for i in pick]


def subset(data: dict[str, np.ndarray], starts: list[float]) -> dict[str, np.ndarray]:
    keep = {}
    for key, arr in data.items():
        t = arr[:, 0]
        mask = np.zeros(len(t), dtype=bool)
        for t0 in starts:
            mask |= (t >= t0 - MARGIN_S) & (t <= t0 + WINDOW_S + MARGIN_S)
        keep[key] = arr[mask].astype(np.float64 if key == "sp" else np.float32)
    keep["window_start_s"] = np.array(starts)
    keep["window_s"] = np.array(WINDOW_S)
    return keep


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--source", type=Path, default=DEFAULT_SOURCE, help="folder with the *.tlog.gz flights")
    args = parser.parse_args(argv)
    OUT.mkdir(parents=True, exist_ok=True)
    for name in FLIGHTS:
        data = read_tlog(args.source / f"{name}.tlog.gz")
        starts = windows(data)
        buf = io.BytesIO()
        np.savez_compressed(buf, **subset(data, starts))
        (OUT / f"{name}.npz").write_bytes(buf.getvalue())
        print(f"{name}: {len(starts)} windows, {len(buf.getvalue()) // 1024} kB")
    return 0


if __name__ == "__main__":
    sys.exit(main())
