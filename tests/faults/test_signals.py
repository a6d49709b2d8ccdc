"""SIGTERM (systemd, docker stop) and SIGHUP (terminal closed) end the flight like Ctrl-C: hold
requested and confirmed, summary printed, logs closed, exit 0. Before issue 9 SIGTERM killed the
app with no hold request and no summary."""

from __future__ import annotations

import signal
import subprocess
import sys

import pytest
from sitl_mock.runner import spawn

from pf_offboard.app.profiles import PX4
from pf_offboard.logs.tlog import read_tlog

from .common import hover, lockstep, write_config

pytestmark = pytest.mark.integration


@pytest.mark.parametrize("signum", [signal.SIGTERM, signal.SIGHUP])
def test_sigterm_and_sighup_hand_back_like_ctrl_c(tmp_path, signum: int) -> None:
    config = write_config(tmp_path)
    name = signal.Signals(signum).name
    with spawn(lockstep("px4", hover())) as mock:
        proc = subprocess.Popen(
            [sys.executable, "-m", "pf_offboard", "fly", "--connect", f"udpout:127.0.0.1:{mock.ports.udp}", "--config",
             str(config), "--airborne", "--log-dir", str(tmp_path / "log")],
            stderr=subprocess.PIPE, text=True,
        )  # fmt: skip
        assert proc.stderr is not None
        lines = []
        for line in proc.stderr:  # the plain (non-TTY) status line comes once a second
            lines.append(line)
            if line.startswith("[following]"):
                proc.send_signal(signum)
                break
        _, err = proc.communicate(timeout=60)
        text = "".join(lines) + err
        assert mock.process.poll() is None
    print("\n" + text[-600:])
    assert proc.returncode == 0, text
    assert f"stop requested ({name}); handed back in AUTO.LOITER (exit 0)" in text
    assert "cross-track RMS" in text and f"logs: {tmp_path / 'log'}" in text  # the summary
    entries = read_tlog(tmp_path / "log" / "flight.tlog")  # complete (closed) log
    modes = [e.message.custom_mode for e in entries if e.direction == "in" and e.message.get_type() == "HEARTBEAT"]
    assert modes[-1] == PX4.hold_custom_mode
    assert (tmp_path / "log" / "flight.csv").stat().st_size > 0
