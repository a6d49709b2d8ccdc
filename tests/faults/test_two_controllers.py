"""One controller at a time, during the flight: a second controller (a second pf-offboard, system 1
component 191 from another port) starts streaming position setpoints to the autopilot while the app
follows. The app sees it — relayed on its link (a router / forwarding autopilot: the mock with
``relay_setpoints``), or in the autopilot's echoed target (POSITION_TARGET_LOCAL_NED carrying a
position the app never sent, PX4 and ArduPilot style) — and ends following: hold requested until
confirmed, exit 8. Before, the two fought for 13.5 s undetected. Against sitl-mock over real
loopback UDP, the end state from the mock's side."""

from __future__ import annotations

import threading
from collections.abc import Callable

import numpy as np
import pytest
from pymavlink.dialects.v20 import common as mavlink2
from sitl_mock.runner import run_in_thread
from sitl_mock.testing import free_udp_port


from pf_offboard.app.fly import envelope_fence
from pf_offboard.config import load_config
from pf_offboard.frames import ned_to_enu

from .attackers import Attacker, fly_udpin, mock_config
from .common import entries, is_mode_request, write_config

pytestmark = pytest.mark.integration

def _other_controller_setpoint(target_ned) -> mavlink2.MAVLink_message:
    ignore = (mavlink2.POSITION_TARGET_TYPEMASK_VX_IGNORE | mavlink2.POSITION_TARGET_TYPEMASK_VY_IGNORE
              | mavlink2.POSITION_TARGET_TYPEMASK_VZ_IGNORE | mavlink2.POSITION_TARGET_TYPEMASK_AX_IGNORE
              | mavlink2.POSITION_TARGET_TYPEMASK_AY_IGNORE | mavlink2.POSITION_TARGET_TYPEMASK_AZ_IGNORE
              | mavlink2.POSITION_TARGET_TYPEMASK_YAW_RATE_IGNORE)  # fmt: skip
    return mavlink2.MAVLink_set_position_target_local_ned_message(
        0, 1, 1, mavlink2.MAV_FRAME_LOCAL_NED, ignore, *(float(v) for v in target_ned), 0, 0, 0, 0, 0, 0, 0.0, 0.0
    )


class OtherController(Attacker):
    """A second controller (system 1, component 191, its own port) holding the vehicle where it is
    (a second app, a ground station's "hold here"): its setpoint follows the vehicle's position, so
    the fight is slow and only the detection ends it (a far target tilts the vehicle past the
    envelope first, which ends the flight too, with exit 5).

    Paced in vehicle time, not on a wall-clock thread: it sends from the mock's own loop (its
    ``on_received`` hook) every 0.5-1.5 ``period_s`` of vehicle time (seeded), from ``start_after_s`` of vehicle
    time into following on, but not before the app's grace for the echoes of its own setpoints
    (ControllerWatch.own_grace_s, wall clock) is over: a fight that begins inside the grace lasts
    as long as the grace in wall time, i.e. longer in vehicle time the faster the lockstep vehicle
    runs. The lockstep vehicle advances only on the setpoints it receives, and the other
    controller's datagram reaches the mock's socket before the app's next setpoint (which answers
    telemetry sent after it), so the two controllers' shares of the fight no longer depend on how
    fast the app runs: with a wall-clock 50 Hz sender started 0.5 s (wall) into following, a
    loaded machine gave the other controller a larger share and a longer fight, which tilted the
    vehicle or took it past the fence first (exit 5, ~1 run in 4 on ardupilot-attitude-echo)."""

    def __init__(self, dest, mock, period_s: float, start_after_s: float = 0.5) -> None:
        super().__init__(dest, [], period_s=period_s, system=1, component=191)
        self.mock = mock
        self.start_after_s = start_after_s
        self.following = threading.Event()  # set by the app's side once it follows (see follow())
        self._grace_over: Callable[[], bool] = lambda: True
        self._next_s: float | None = None
        self._rng = np.random.default_rng(0)

    def follow(self, flight) -> None:
        """The app began following (called on its side): its echo grace ends own_grace_s from now."""
        clock, until = flight.clock, flight.clock() + flight.controllers.own_grace_s
        self._grace_over = lambda: clock() > until
        self.following.set()

    def _on_received(self, msg, addr) -> None:  # on the mock's loop, for every frame it accepts
        if not self.following.is_set() or addr == self.sock.getsockname():  # not on its own setpoints
            return
        m = self.mock.mock
        if self._next_s is None:
            self._next_s = m.time_s + self.start_after_s
        if m.time_s + 1e-9 < self._next_s or not self._grace_over():
            return
        # the next one 0.5..1.5 periods on (seeded): a fixed period would alias with the autopilot's
        # 10 Hz target echo (ArduPilot echoes only a position target flown at that instant), so the
        # evidence would come every time or never depending on the phase
        self._next_s = max(self._next_s + self.period_s * (0.5 + self._rng.random()), m.time_s)
        self.messages = [_other_controller_setpoint(tuple(m.truth.position_ned_m))]
        for out in self.messages:
            self.sock.sendto(out.pack(self.mav), self.dest)
            self.mav.seq = (self.mav.seq + 1) & 0xFF
            self.sent += 1

    def start(self) -> OtherController:
        self.mock.call(lambda m: setattr(m, "on_received", self._on_received))
        return self

    def stop(self) -> None:
        self.mock.call(lambda m: setattr(m, "on_received", None))
        self.sock.close()


@pytest.mark.parametrize(
    ("profile", "output", "relay"),
    [("px4", "acceleration", True), ("px4", "acceleration", False), ("px4", "attitude", False), ("ardupilot", "attitude", False)],
    ids=["px4-relayed", "px4-acceleration-echo", "px4-attitude-echo", "ardupilot-attitude-echo"],
)
def test_a_second_controller_during_the_flight_ends_it_in_the_hold(tmp_path, profile: str, output: str, relay: bool) -> None:
    app_port = free_udp_port()
    # Every setpoint switches the autopilot between the two controllers: on a loaded machine the
    # fight jerks the mock's fast vehicle past the tilt look-ahead (60 deg) or the paper path's tight
    # fence in some runs before the evidence is in (exit 5, safe too); with a wider envelope the
    # detection is what ends the flight
    config = write_config(tmp_path, safety={"max_tilt_deg": 80.0, "fence_margin_m": 4.0, "max_path_distance_m": 5.0})
    fence = envelope_fence(load_config(config))
    flags = ["--airborne", "--duration", "30", "--output", output]
    if profile == "ardupilot":
        flags.append("--set-guid-options")
    with run_in_thread(mock_config(app_port, profile=profile, relay_setpoints=relay)) as mock:
        other = OtherController(("127.0.0.1", mock.ports.udp), mock, 0.03).start()

        def on_start(flight) -> None:
            original = flight._activate

            def activate() -> None:
                original()
                other.follow(flight)  # the other controller starts 0.5 s (vehicle time) into following, after the echo grace

            flight._activate = activate

        try:
            outcome, printed = fly_udpin(app_port, config, tmp_path / "log", *flags, on_start=on_start)
        finally:
            other.stop()
        mode, armed, position_enu, events = mock.call(lambda m: (
            m.autopilot.mode.name, bool(m.autopilot.armed), ned_to_enu(np.array(m.truth.position_ned_m)),
            [e.text for e in m.autopilot.log]))  # fmt: skip
        relayed = mock.call(lambda m: m.relayed)
    hold = "AUTO.LOITER" if profile == "px4" else "BRAKE"
    modes = [e for e in events if e.startswith("mode ")]
    print(f"\n{profile} {output} relay={relay}: exit {outcome.exit_code}, {outcome.reason}; other sent {other.sent}, "
          f"mock relayed {relayed}; vehicle {mode} at {position_enu.round(2)}; modes {modes}")  # fmt: skip
    assert other.following.is_set() and other.sent > 0
    assert outcome.exit_code == 8, printed
    assert "another controller is flying the vehicle" in outcome.reason
    assert f"{hold} requested, confirmed" in outcome.reason
    assert (outcome.link_counters.foreign_setpoint > 0) == relay  # relayed on the link, or not at all
    assert (mode, armed) == (hold, True)
    assert not any("RTL" in m for m in modes), modes
    assert modes[-1].endswith(f"-> {hold}"), modes
    assert fence.violation(position_enu) == "", position_enu  # inside the fence, above its floor
    assert position_enu[2] >= fence.floor_m
    log = entries(tmp_path / "log")
    sent_modes = [int(e.message.param2) for e in log if e.direction == "out" and is_mode_request(e.message)]
    assert sent_modes, "no hold request was sent"
    active = [r for r in outcome.records if r.active]
    assert active and active[-1].time_s - active[0].time_s < 25.0  # ended long before --duration


def test_no_other_controller_no_verdict(tmp_path) -> None:
    """Without a second controller, a flight with relaying on and the echoed target streamed runs to
    its end (no false positive from our own setpoints' echo or our take-off position setpoints)."""
    app_port = free_udp_port()
    config = write_config(tmp_path)
    for profile, output in (("px4", "acceleration"), ("px4", "attitude"), ("ardupilot", "attitude")):
        flags = ["--airborne", "--duration", "4", "--output", output] + (["--set-guid-options"] if profile == "ardupilot" else [])
        with run_in_thread(mock_config(app_port, profile=profile, relay_setpoints=True)) as mock:
            outcome, printed = fly_udpin(app_port, config, tmp_path / f"{profile}-{output}", *flags)
            relayed = mock.call(lambda m: m.relayed)
        assert outcome.exit_code == 0, printed
        assert relayed == 0
        echoes = [e for e in entries(tmp_path / f"{profile}-{output}") if e.direction == "in"
                  and e.message.get_type() == "POSITION_TARGET_LOCAL_NED"]  # fmt: skip
        if (profile, output) == ("px4", "acceleration"):
            assert echoes  # PX4 echoes our acceleration setpoints: the evidence is really there to read
