"""COMMAND_ACKs are matched on command *and* target: the autopilot answering another GCS's mode
request with DENIED (target system 255) while the app engages must not abort the app's engagement
(it did: "mode OFFBOARD refused by the autopilot", exit 3)."""

from __future__ import annotations

import pytest
from sitl_mock.config import FaultConfig
from sitl_mock.runner import run_in_thread
from sitl_mock.testing import free_udp_port

from app.flights import write_config

from .attackers import fly_udpin, mock_config

pytestmark = pytest.mark.integration


def test_a_denied_ack_for_another_gcs_is_ignored(tmp_path) -> None:
    app_port = free_udp_port()
    config = write_config(tmp_path)
    with run_in_thread(mock_config(app_port, faults=FaultConfig(foreign_denied_ack=True))) as mock:
        outcome, printed = fly_udpin(app_port, config, tmp_path / "log", "--airborne", "--duration", "2")
        mode, armed, events = mock.call(lambda m: (m.autopilot.mode.name, bool(m.autopilot.armed), [e.text for e in m.autopilot.log]))
    modes = [e for e in events if e.startswith("mode ")]
    assert outcome.exit_code == 0, printed
    assert "handed back in AUTO.LOITER" in outcome.reason
    assert modes == ["mode AUTO.LOITER -> OFFBOARD", "mode OFFBOARD -> AUTO.LOITER"], modes
    assert (mode, armed) == ("AUTO.LOITER", True)
    assert outcome.link_counters.foreign_ack >= 2  # the OFFBOARD and the hold requests each drew one
