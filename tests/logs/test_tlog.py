"""The .tlog writer/reader: pymavlink-compatible, direction by source component, strict errors."""

from __future__ import annotations

from pathlib import Path

import pytest
from pymavlink import mavutil
from pymavlink.dialects.v20 import ardupilotmega as mavlink

from pf_offboard.errors import InputError
from pf_offboard.logs.tlog import OWN_COMPONENT_ID, LogError, TlogWriter, read_tlog

T0 = 1_780_000_000.0


def _write_sample(path: Path, n: int = 20) -> list[bytes]:
    ap = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    us = mavlink.MAVLink(None, srcSystem=255, srcComponent=OWN_COMPONENT_ID)
    frames: list[bytes] = []
    with TlogWriter.open(path) as w:
        for i in range(n):
            inbound = ap.local_position_ned_encode(4 * i, 0.1 * i, -0.2 * i, -2.0, 0.5, 0.25, 0.0).pack(ap)
            outbound = us.set_position_target_local_ned_encode(
                4 * i, 1, 1, mavlink.MAV_FRAME_LOCAL_NED, 0x0C3F, 0, 0, 0, 0, 0, 0, 0.01 * i, -0.02 * i, 0.3, 0, 0
            ).pack(us)
            w.write(inbound, T0 + 0.004 * i)
            w.write(outbound, T0 + 0.004 * i + 0.001)
            frames += [bytes(inbound), bytes(outbound)]
    return frames


def test_round_trip_and_direction(tmp_path: Path) -> None:
    path = tmp_path / "a.tlog"
    frames = _write_sample(path)
    entries = read_tlog(path)
    assert [e.frame for e in entries] == frames
    assert [e.direction for e in entries] == ["in", "out"] * 20
    assert entries[3].time_unix_s == pytest.approx(T0 + 0.005, abs=1e-6)
    assert entries[3].message.get_type() == "SET_POSITION_TARGET_LOCAL_NED"
    assert entries[3].message.afx == pytest.approx(0.01, abs=1e-7)
    # Offsets point at the record start: 8-byte stamp + frame.
    assert entries[1].offset == 8 + len(frames[0])


def test_pymavlink_reads_our_tlog(tmp_path: Path) -> None:
    path = tmp_path / "a.tlog"
    _write_sample(path, n=5)
    conn = mavutil.mavlink_connection(str(path))
    types = []
    while (msg := conn.recv_match()) is not None:
        types.append(msg.get_type())
        assert abs(msg._timestamp - T0) < 1.0
    assert types == ["LOCAL_POSITION_NED", "SET_POSITION_TARGET_LOCAL_NED"] * 5


def test_own_system_id_narrows_direction(tmp_path: Path) -> None:
    path = tmp_path / "a.tlog"
    _write_sample(path, n=2)
    assert {e.direction for e in read_tlog(path, own_system_id=42)} == {"in"}


def test_truncated_log_names_offset(tmp_path: Path) -> None:
    path = tmp_path / "a.tlog"
    frames = _write_sample(path, n=3)
    data = path.read_bytes()
    path.write_bytes(data[:-5])
    last_offset = len(data) - 8 - len(frames[-1])
    with pytest.raises(LogError, match=rf"@ byte {last_offset}: truncated record 5"):
        read_tlog(path)


def test_corrupt_crc_names_offset(tmp_path: Path) -> None:
    path = tmp_path / "a.tlog"
    frames = _write_sample(path, n=3)
    data = bytearray(path.read_bytes())
    off = 8 + len(frames[0])  # second record
    data[off + 8 + 12] ^= 0xFF  # a payload byte of its frame
    path.write_bytes(bytes(data))
    with pytest.raises(LogError, match=rf"@ byte {off}: record 1: corrupt MAVLink frame: invalid MAVLink CRC"):
        read_tlog(path)


def test_bad_start_byte_and_bad_timestamp(tmp_path: Path) -> None:
    path = tmp_path / "a.tlog"
    frames = _write_sample(path, n=2)
    data = bytearray(path.read_bytes())
    data[8] = 0x55
    path.write_bytes(bytes(data))
    with pytest.raises(LogError, match=r"@ byte 0: record 0: bad MAVLink start byte 0x55"):
        read_tlog(path)
    data = bytearray(path.read_bytes())
    data[8] = 0xFD
    off = 8 + len(frames[0])
    data[off] = 0xFF  # most significant timestamp byte
    path.write_bytes(bytes(data))
    with pytest.raises(LogError, match=rf"@ byte {off}: record 1: timestamp .* not a plausible UNIX time"):
        read_tlog(path)


def test_missing_and_empty_files_are_input_errors(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="cannot read"):
        read_tlog(tmp_path / "nope.tlog")
    (tmp_path / "e.tlog").write_bytes(b"")
    with pytest.raises(InputError, match="empty file"):
        read_tlog(tmp_path / "e.tlog")


def test_writer_rejects_non_frames(tmp_path: Path) -> None:
    with TlogWriter.open(tmp_path / "a.tlog") as w, pytest.raises(ValueError, match="not a MAVLink frame"):
        w.write(b"hello", T0)


def test_flight_log_writes_siblings(tmp_path: Path) -> None:
    from pf_offboard.logs.flightlog import FlightLog, FlightLogPaths

    cfg = tmp_path / "c.yaml"
    cfg.write_text("speed_m_s: 1.0\n")
    ap = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    with FlightLog.open(tmp_path / "out", name="f1", config_path=cfg) as log:
        log.frame(ap.heartbeat_encode(2, 12, 0, 0, 3, 3).pack(ap), T0)
    paths = FlightLogPaths.beside(tmp_path / "out" / "f1.tlog")
    assert paths == log.paths
    assert paths.config_yaml.read_text() == "speed_m_s: 1.0\n"
    assert [e.message.get_type() for e in read_tlog(paths.tlog)] == ["HEARTBEAT"]
    assert paths.steps_csv.read_text().startswith("time_s,mode,active,")
