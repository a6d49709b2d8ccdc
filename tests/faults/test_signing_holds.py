"""Signing that holds, against sitl-mock over real loopback UDP: a frame with a wrong signature
(no key needed) and a timestamp far ahead never stalls the genuine stream (app and mock check the
signature before the timestamp), and a genuine signed frame replayed from another port is refused
by the mock (one signing state per link, as PX4 / ArduPilot keep it)."""

from __future__ import annotations

import socket

import pytest
from pymavlink.dialects.v20 import common as mavlink2
from sitl_mock.runner import run_in_thread
from sitl_mock.testing import free_udp_port

from app.flights import write_config

from .attackers import Attacker, fly_udpin, mock_config

pytestmark = pytest.mark.integration

FUTURE = 10**15  # a signing timestamp centuries ahead (10 µs units since 2015; now is ~3.8e13)


def _key(tmp_path, text: str = "correct horse battery staple") -> str:
    path = tmp_path / "key"
    path.write_text(text + "\n")
    path.chmod(0o600)
    return str(path)


def _forged(msg, system: int, component: int) -> bytes:
    mav = mavlink2.MAVLink(None, srcSystem=system, srcComponent=component)
    mav.signing.secret_key = bytes(32)  # not the link's key
    mav.signing.sign_outgoing = True
    mav.signing.timestamp = FUTURE
    return bytes(msg.pack(mav))


def test_one_forged_frame_does_not_switch_signing_off(tmp_path) -> None:
    """Before the autopilot is found, a forged HEARTBEAT as sysid 1 / compid 1 reaches the app; during
    the flight forged commands with the app's own ids reach the mock. Old pymavlink behaviour: the
    app never connects (every genuine HEARTBEAT "old"), or the mock drops every setpoint after the
    forged one (offboard loss, RTL). Now the flight completes and hands back in AUTO.LOITER."""
    app_port = free_udp_port()
    key = _key(tmp_path)
    config = write_config(tmp_path)
    hb = mavlink2.MAVLink_heartbeat_message(mavlink2.MAV_TYPE_QUADROTOR, mavlink2.MAV_AUTOPILOT_PX4, 0x91, 6 << 16, 4, 3)
    cmd = mavlink2.MAVLink_command_long_message(1, 1, mavlink2.MAV_CMD_DO_SET_MODE, 0, 1, 3, 0, 0, 0, 0, 0)
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", 0))
    # forged HEARTBEATs at the app's port from before it opens it until it has found the autopilot
    early = Attacker(("127.0.0.1", app_port), [hb], period_s=0.005)
    early.mav.signing.secret_key, early.mav.signing.sign_outgoing, early.mav.signing.timestamp = bytes(32), True, FUTURE
    early.start()
    try:
        with run_in_thread(mock_config(app_port, signing_key_file=key)) as mock:
            mock_port = mock.ports.udp

            def attack(_bridge) -> None:  # once the app has found the autopilot: at the mock, as the app
                early.stop()
                for component in (191, 190):
                    sock.sendto(_forged(cmd, 1, component), ("127.0.0.1", mock_port))

            outcome, printed = fly_udpin(app_port, config, tmp_path / "log", "--airborne", "--duration", "3",
                                         "--signing-key", key, on_start=attack)  # fmt: skip
            mode, armed, modes = mock.call(lambda m: (m.autopilot.mode.name, bool(m.autopilot.armed), [e.text for e in m.autopilot.log]))
            refused = mock.call(lambda m: m.rejected_signature)
    finally:
        early.stop()
        sock.close()
    assert outcome.exit_code == 0, printed
    assert "handed back in AUTO.LOITER" in outcome.reason
    assert (mode, armed) == ("AUTO.LOITER", True)
    assert not any("RTL" in t for t in modes), modes
    assert refused >= 2  # the forged commands, refused by signature
    assert outcome.link_counters.bad_signature >= 1  # the forged HEARTBEAT, counted by the app


def test_a_signed_frame_replayed_from_another_port_is_refused(tmp_path) -> None:
    """The app's own signed mode requests, captured as sent and replayed to the mock from a new UDP
    port after the flight's hand-back: one signing state for the whole UDP link, so they are old
    frames, refused and never answered (per-address state accepted them as a new stream)."""
    app_port = free_udp_port()
    key = _key(tmp_path)
    config = write_config(tmp_path)
    captured: list[bytes] = []

    def capture(bridge) -> None:
        link = bridge.link
        logged = link.on_sent

        def on_sent(msg) -> None:
            if msg.get_type() == "COMMAND_LONG" and msg.command == mavlink2.MAV_CMD_DO_SET_MODE:
                captured.append(bytes(msg.get_msgbuf()))
            if logged is not None:
                logged(msg)

        link.on_sent = on_sent

    with run_in_thread(mock_config(app_port, signing_key_file=key)) as mock:
        outcome, printed = fly_udpin(app_port, config, tmp_path / "log", "--airborne", "--duration", "2",
                                     "--signing-key", key, on_start=capture)  # fmt: skip
        before = mock.call(lambda m: m.rejected_signature)
        replay = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        replay.bind(("127.0.0.1", 0))
        replay.settimeout(0.3)
        answered = 0
        try:
            for frame in captured:
                replay.sendto(frame, ("127.0.0.1", mock.ports.udp))
            try:
                while replay.recv(65535):
                    answered += 1
            except TimeoutError:
                pass
        finally:
            replay.close()
        mock.call(lambda m: None)  # the mock's loop has handled the datagrams
        after = mock.call(lambda m: m.rejected_signature)
        mode = mock.call(lambda m: m.autopilot.mode.name)
    assert outcome.exit_code == 0, printed
    assert len(captured) >= 2  # OFFBOARD and the hold
    assert all(f[2] & 1 for f in captured)  # incompat flag: signed
    assert after - before == len(captured), (before, after, len(captured))
    assert answered == 0 and mode == "AUTO.LOITER"  # the replayed OFFBOARD request was not obeyed
