"""Link faults against sitl-mock over real loopback UDP (issue 9, item 3): spoofing from another
port, signing. End state read from the mock's side; exit code and message from the app's."""

from __future__ import annotations

import numpy as np
import pytest
from pymavlink.dialects.v20 import common as mavlink2
from sitl_mock.runner import run_in_thread
from sitl_mock.testing import free_udp_port

from app.flights import RATE_HZ, write_config
from pf_offboard.config import load_config
from pf_offboard.frames import ned_to_enu
from pf_offboard.path.projection import Projector
from .attackers import POSCTL_PX4, Attacker, attacking, fly_udpin, mock_config

pytestmark = pytest.mark.integration


def _mock_state(mock) -> tuple[str, bool, np.ndarray]:
    return mock.call(lambda m: (m.autopilot.mode.name, bool(m.autopilot.armed), np.array(m.truth.position_ned_m)))


def test_spoofed_takeover_heartbeat_and_position_from_another_port_change_nothing(tmp_path) -> None:
    """From another port, as sysid 1 / compid 1: from the start, a GCS-type HEARTBEAT claiming
    POSCTL (the fake takeover) and LOCAL_POSITION_NED 50 m away; once the app has found the
    autopilot, also an autopilot-type HEARTBEAT claiming POSCTL. No takeover, the spoofed position
    is never used, the app flies its duration and hands back; the spoofer is sent nothing."""
    app_port = free_udp_port()
    config = write_config(tmp_path)
    gcs_takeover = mavlink2.MAVLink_heartbeat_message(mavlink2.MAV_TYPE_GCS, mavlink2.MAV_AUTOPILOT_INVALID, 0x91, POSCTL_PX4, 4, 3)
    ap_takeover = mavlink2.MAVLink_heartbeat_message(mavlink2.MAV_TYPE_QUADROTOR, mavlink2.MAV_AUTOPILOT_PX4, 0x91, POSCTL_PX4, 4, 3)
    far = mavlink2.MAVLink_local_position_ned_message(1000, 50.0, 0.0, -2.0, 0.0, 0.0, 0.0)
    dest = ("127.0.0.1", app_port)
    late = Attacker(dest, [ap_takeover, gcs_takeover, far], period_s=0.01)
    with run_in_thread(mock_config(app_port)) as mock:
        with attacking(dest, [gcs_takeover, far], period_s=0.01) as early:
            try:
                outcome, printed = fly_udpin(app_port, config, tmp_path / "log", "--airborne", "--duration", "6",
                                             on_start=lambda _bridge: late.start())  # fmt: skip
            finally:
                late.stop()
        mode, armed, position_ned = _mock_state(mock)
    assert outcome.exit_code == 0, printed
    assert "duration 6 s reached; handed back in AUTO.LOITER" in outcome.reason
    assert (mode, armed) == ("AUTO.LOITER", True)  # the app's hand-back, not a takeover
    # On the paper path (wherever along it 6 s of flight ended), not chasing the spoofed 50 m.
    path = load_config(config).path.spline()
    position_enu = ned_to_enu(position_ned)
    on_path = path.eval(Projector(path).update(position_enu)).sigma
    assert np.linalg.norm(position_enu - on_path) < 0.5, (position_enu, on_path)
    positions = np.array([r.position_enu_m for r in outcome.records])
    assert np.abs(positions).max() < 5.0  # no step ever saw the spoofed position
    counters = outcome.link_counters
    sent = early.sent + late.sent
    assert early.sent > 50 and late.sent > 50 and counters.foreign_peer >= 0.5 * sent, (early.sent, late.sent, counters)
    assert early.received == 0 and late.received == 0  # udpin sends only to the locked peer
    assert f"rejected {counters.foreign_peer} from another address" in printed


def _key_file(tmp_path, name: str, text: str) -> str:
    path = tmp_path / name
    path.write_text(text + "\n")
    path.chmod(0o600)  # key files are checked like ssh keys: owner only
    return str(path)


def test_signed_link_flies_and_the_mock_refuses_unsigned_commands(tmp_path) -> None:
    """Same key on both ends: the flight completes. Meanwhile an unsigned client and one with
    another key try to take the vehicle (DO_SET_MODE POSCTL, disarm): refused, never answered."""
    app_port = free_udp_port()
    key = _key_file(tmp_path, "key", "correct horse battery staple")
    other = _key_file(tmp_path, "other", "0" * 64)
    config = write_config(tmp_path)
    commands = [
        mavlink2.MAVLink_command_long_message(1, 1, mavlink2.MAV_CMD_DO_SET_MODE, 0, 1, 3, 0, 0, 0, 0, 0),
        mavlink2.MAVLink_command_long_message(1, 1, mavlink2.MAV_CMD_COMPONENT_ARM_DISARM, 0, 0, 21196, 0, 0, 0, 0, 0),
    ]
    with run_in_thread(mock_config(app_port, signing_key_file=key)) as mock:
        mock_port = mock.ports.udp
        with attacking(("127.0.0.1", mock_port), commands, period_s=0.02, system=255, component=190) as unsigned:
            wrong = attacking(("127.0.0.1", mock_port), commands, period_s=0.02, system=255, component=190)
            with wrong as wrongly_signed:
                from pf_offboard.app.signing import read_key_file

                wrongly_signed.mav.signing.secret_key = read_key_file(other)
                wrongly_signed.mav.signing.sign_outgoing = True
                wrongly_signed.mav.signing.timestamp = 10**12
                outcome, printed = fly_udpin(app_port, config, tmp_path / "log", "--airborne", "--duration", "4", "--signing-key", key)
        mode, armed, _ = _mock_state(mock)
        refused = mock.call(lambda m: m.rejected_signature)
        good = mock.call(lambda m: sum(p.mav.signing.goodsig_count for p in m._udp_peers.values()))
    assert outcome.exit_code == 0, printed
    assert (mode, armed) == ("AUTO.LOITER", True)
    assert refused >= unsigned.sent + wrongly_signed.sent - 4 and unsigned.sent > 10 and wrongly_signed.sent > 10
    assert unsigned.received == 0 and wrongly_signed.received == 0  # not answered, not sent telemetry
    assert good > 2.0 * RATE_HZ  # the app's setpoints arrived signed (4 s of them)
    assert outcome.link_counters.bad_signature == 0 and "link                signed;" in printed


def test_app_with_signing_ignores_unsigned_telemetry(tmp_path) -> None:
    """The app has a key, the autopilot does not sign: nothing it sends is believed, so the app
    never finds an autopilot and sends it nothing (exit 3, the refusals named); the vehicle is
    left as it was."""
    app_port = free_udp_port()
    key = _key_file(tmp_path, "key", "a passphrase")
    config = write_config(tmp_path)
    with run_in_thread(mock_config(app_port)) as mock:
        outcome, printed = fly_udpin(app_port, config, tmp_path / "log", "--airborne", "--duration", "4",
                                     "--signing-key", key, heartbeat_timeout_s=2.0)  # fmt: skip
        mode, armed, _ = _mock_state(mock)
        received = mock.call(lambda m: m.received)
    assert outcome.exit_code == 3
    assert "no HEARTBEAT from an autopilot" in outcome.reason and "frames refused: unsigned or signed with another key" in outcome.reason
    assert "link error" in printed
    assert (mode, armed) == ("AUTO.LOITER", True) and received == 0  # hover spawn: untouched


def test_mock_with_signing_refuses_an_unsigned_app(tmp_path) -> None:
    """The autopilot signs, the app does not: the app's HEARTBEATs and requests are refused and the
    app cannot verify the autopilot either; nothing is flown."""
    app_port = free_udp_port()
    key = _key_file(tmp_path, "key", "f" * 64)
    config = write_config(tmp_path)
    with run_in_thread(mock_config(app_port, signing_key_file=key)) as mock:
        # --ready-timeout: the refused app waits for a position estimate that never comes;
        # --command-timeout: each refused parameter read is given up after 1 s instead of 5 s (it
        # is re-sent every 0.5 s meanwhile, so each is still refused more than once: ~20 s -> ~5 s)
        outcome, printed = fly_udpin(app_port, config, tmp_path / "log", "--airborne", "--duration", "4",
                                     "--ready-timeout", "2", "--command-timeout", "1", heartbeat_timeout_s=2.0)  # fmt: skip
        mode, armed, _ = _mock_state(mock)
        refused = mock.call(lambda m: m.rejected_signature)
        steps = mock.call(lambda m: m.steps)
    # unsigned, the app cannot tell a signed frame's signature is valid, but pymavlink parses it:
    # it finds the autopilot, yet every request it sends is refused, so nothing is confirmed
    assert outcome.exit_code == 3, printed
    assert refused > 0 and mode == "AUTO.LOITER" and armed and steps == 0  # no setpoint ever accepted
    print(f"\nunsigned app vs signing mock: {outcome.reason}; the mock refused {refused} frames")
