"""Bad input against a live autopilot: a malformed endpoint, a device or a 5000-character name as the
config, a FIFO as the signing key — one line, exit 2, and the autopilot receives nothing."""

from __future__ import annotations

import os

import pytest
from sitl_mock.runner import run_in_thread
from sitl_mock.testing import free_udp_port

from app.flights import write_config
from pf_offboard.cli import main

from .attackers import mock_config

pytestmark = pytest.mark.integration


def test_bad_input_sends_nothing(tmp_path, capsys) -> None:
    app_port = free_udp_port()
    config = str(write_config(tmp_path))
    fifo = tmp_path / "fifo"
    os.mkfifo(fifo, 0o600)
    good = f"udpin:127.0.0.1:{app_port}"
    cases = [
        ("udpout:256.1.1.1:14540", config, None, "is not an IPv4 address"),
        (good, "/dev/zero", None, "/dev/zero"),
        (good, "c" * 5000, None, "File name too long"),
        (good, config, str(fifo), "not a regular file"),
        ("serial:/dev/zero:57600", config, None, "not a serial port"),
    ]
    with run_in_thread(mock_config(app_port)) as mock:
        for endpoint, cfg, key, why in cases:
            argv = ["fly", "--connect", endpoint, "--config", cfg, "--airborne", "--duration", "2", "--log-dir", str(tmp_path / "log")]
            if key is not None:
                argv += ["--signing-key", key]
            code = main(argv)
            err = capsys.readouterr().err
            lines = [line for line in err.splitlines() if line.strip()]
            assert code == 2 and len(lines) == 1 and why in lines[0], (endpoint[:40], cfg[:40], err)
        received = mock.call(lambda m: m.received)
    assert received == 0  # not a HEARTBEAT, not a request
