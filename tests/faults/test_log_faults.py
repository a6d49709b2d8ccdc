"""Flight control never depends on logging: a full disk (every log file on /dev/full, which fails
each write with ENOSPC) degrades the logs with one warning per file and never reaches the receive
callback or the keep-alive; the flight completes and hands back. Log directories are never shared
by two runs."""

from __future__ import annotations

import os
import threading

import pytest
from sitl_mock.runner import run_in_thread
from sitl_mock.testing import free_udp_port

from app.flights import write_config
from pf_offboard.logs.flightlog import FlightLog

from .attackers import fly_udpin, mock_config


@pytest.mark.integration
@pytest.mark.skipif(not os.path.exists("/dev/full"), reason="needs /dev/full (Linux)")
def test_a_full_disk_degrades_the_logs_and_the_flight_completes(tmp_path) -> None:
    app_port = free_udp_port()
    config = write_config(tmp_path)
    log_dir = tmp_path / "log"
    log_dir.mkdir()
    for name in ("flight.tlog", "flight.csv", "summary.json"):
        (log_dir / name).symlink_to("/dev/full")
    with run_in_thread(mock_config(app_port)) as mock:
        outcome, printed = fly_udpin(app_port, config, log_dir, "--airborne", "--duration", "3")
        mode, armed, alt, events = mock.call(lambda m: (m.autopilot.mode.name, bool(m.autopilot.armed), -float(m.truth.position_ned_m[2]),
                                                         [e.text for e in m.autopilot.log]))  # fmt: skip
    print(f"\nfull disk: exit {outcome.exit_code}, {outcome.reason}; vehicle {mode} at {alt:.2f} m")
    assert outcome.exit_code == 0, printed
    assert "duration 3 s reached; handed back in AUTO.LOITER" in outcome.reason
    assert (mode, armed) == ("AUTO.LOITER", True) and alt > 1.0
    assert not any("RTL" in e or "failsafe" in e.lower() for e in events), events
    for name in ("flight.tlog", "flight.csv"):
        warned = [line for line in printed.splitlines() if f"{name} stopped: write failed: No space left on device" in line]
        assert len(warned) == 1, printed  # once per file, not once per frame
    assert "Traceback" not in printed


def test_log_write_errors_and_the_size_bound_never_raise(tmp_path) -> None:
    """The writers' own errors (ENOSPC on write, flush, close) and the size bound: one warning per
    file, nothing raised, later frames ignored."""
    warnings: list[str] = []
    log = FlightLog.open(tmp_path / "bounded", warn=warnings.append, max_file_bytes=1000)
    frame = bytes([0xFD, 9, 0, 0, 0, 1, 1, 0, 0, 0]) + bytes(9) + bytes(2)
    for _ in range(100):
        log.frame(frame, 1.7e9)
    log.close()
    assert len(warnings) == 1 and "size limit" in warnings[0]
    assert (tmp_path / "bounded" / "flight.tlog").stat().st_size <= 1000
    if os.path.exists("/dev/full"):
        d = tmp_path / "full"
        d.mkdir()
        (d / "flight.tlog").symlink_to("/dev/full")
        (d / "flight.csv").symlink_to("/dev/full")
        warnings.clear()
        log = FlightLog.open(d, warn=warnings.append)
        for _ in range(2000):
            log.frame(frame, 1.7e9)
        log.flush()
        log.close()  # the CSV's header fails only here
        assert sorted(w.split(" stopped")[0] for w in warnings) == [f"log {d / 'flight.csv'}", f"log {d / 'flight.tlog'}"], warnings


def test_concurrent_runs_never_share_a_default_log_dir(tmp_path, monkeypatch) -> None:
    """Many runs started in the same second without --log-dir: each gets its own directory."""
    from pf_offboard.app.fly import default_log_dir

    monkeypatch.chdir(tmp_path)
    made: list[str] = []
    lock = threading.Lock()

    def start() -> None:
        d = default_log_dir()
        with lock:
            made.append(str(d))

    threads = [threading.Thread(target=start) for _ in range(16)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert len(set(made)) == 16 and all((tmp_path / d).is_dir() for d in made)
