"""Trim a PX4 ULog to what identify / plot read, for a small test fixture.

Keeps the header, every definition and parameter, and of the data only the topics
``pf_offboard.logs.ulog`` uses (multi-instance 0), from ``--from`` to ``--to`` seconds of boot
time, every ``--every``-th sample of the fast topics. The result is a valid ULog (pyulog reads it).

    python scripts/trim_ulog.py IN.ulg OUT.ulg [--from S] [--to S] [--every N]
"""

from __future__ import annotations

import argparse
import struct
from pathlib import Path

KEEP = ("vehicle_local_position", "vehicle_local_position_groundtruth", "vehicle_attitude", "vehicle_angular_velocity",
        "vehicle_status", "trajectory_setpoint", "vehicle_control_mode", "vehicle_attitude_setpoint", "vehicle_rates_setpoint")  # fmt: skip
FAST = ("vehicle_local_position", "vehicle_attitude", "vehicle_angular_velocity", "vehicle_local_position_groundtruth", "vehicle_attitude_setpoint",
        "vehicle_rates_setpoint")  # fmt: skip


def trim(src: bytes, t0_s: float, t1_s: float, every: int) -> bytes:
    header_len = 16
    out = bytearray(src[:header_len])
    pos = header_len
    ids: dict[int, str] = {}
    counts: dict[int, int] = {}
    while pos + 3 <= len(src):
        size, kind = struct.unpack_from("<HB", src, pos)
        end = pos + 3 + size
        if end > len(src):
            break
        body = src[pos + 3 : end]
        keep = True
        if kind == ord("A"):  # subscription: multi_id, msg_id, name
            multi_id, msg_id = struct.unpack_from("<BH", body)
            name = body[3:].decode(errors="replace")
            if name in KEEP and multi_id == 0:
                ids[msg_id] = name
            else:
                keep = False
        elif kind == ord("D"):
            (msg_id,) = struct.unpack_from("<H", body)
            name = ids.get(msg_id)
            if name is None:
                keep = False
            else:
                (timestamp_us,) = struct.unpack_from("<Q", body, 2)
                counts[msg_id] = counts.get(msg_id, 0) + 1
                keep = t0_s <= timestamp_us * 1e-6 <= t1_s and (name not in FAST or counts[msg_id] % every == 0)
        elif kind in (ord("L"), ord("C"), ord("S"), ord("O"), ord("R")):  # log text, tagged log, sync, dropout, remove
            keep = False
        if keep:
            out += src[pos:end]
        pos = end
    return bytes(out)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("src")
    ap.add_argument("dst")
    ap.add_argument("--from", dest="t0", type=float, default=0.0)
    ap.add_argument("--to", dest="t1", type=float, default=1e9)
    ap.add_argument("--every", type=int, default=1)
    args = ap.parse_args()
    data = trim(Path(args.src).read_bytes(), args.t0, args.t1, args.every)
    Path(args.dst).write_bytes(data)
    print(f"{args.dst}: {len(data) / 1e6:.2f} MB")


if __name__ == "__main__":
    main()
