"""Shared set-up of the fault tests: the app on ``udpin`` (PX4 SITL style: the autopilot sends to the
app's port), sitl-mock in lockstep in a thread (so its end state can be read), attackers on other
loopback ports."""

from __future__ import annotations

import io
import socket
import threading
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path

from pymavlink.dialects.v20 import common as mavlink2
from sitl_mock.config import MockConfig, SpawnSpec

from pf_offboard.app.fly import FlyOutcome, fly

from app.flights import RATE_HZ, fly_args  # tests/ is on sys.path (pytest rootdir of the test packages)

HOVER_NED = (-3.0, 0.0, -2.0)  # beside the paper path's start, 1.5 m off it
OFFBOARD_PX4 = 6 << 16
POSCTL_PX4 = 3 << 16


def mock_config(app_port: int, profile: str = "px4", spawn: str = "hover:" + ",".join(map(str, HOVER_NED)), **kw: object) -> MockConfig:
    """Lockstep mock whose UDP link sends to the app's ``udpin`` port (and answers its peers)."""
    return MockConfig(vehicle="fast", profile=profile, spawn=SpawnSpec.parse(spawn), udp_local_port=0, udp_remote=("127.0.0.1", app_port),
                      lockstep=True, lockstep_dt_s=1.0 / RATE_HZ, **kw)  # fmt: skip


def fly_udpin(app_port: int, config: Path, log_dir: Path, *flags: str, heartbeat_timeout_s: float = 5.0,
              on_start: Callable[[object], None] | None = None) -> tuple[FlyOutcome, str]:  # fmt: skip
    """Run ``fly`` on ``udpin:127.0.0.1:PORT``; returns the outcome and everything it printed.
    ``on_start(bridge)`` runs once the autopilot is identified (the link locked to its address)."""
    stream = io.StringIO()
    args = fly_args("--connect", f"udpin:127.0.0.1:{app_port}", "--config", str(config), "--log-dir", str(log_dir),
                    "--heartbeat-timeout", str(heartbeat_timeout_s), "--quiet", *flags)  # fmt: skip
    outcome = fly(args, status_stream=stream, on_start=on_start)
    return outcome, stream.getvalue()


class Attacker:
    """A sender on its own loopback port packing real MAVLink frames with someone else's ids.

    ``frames`` are sent in turn to ``dest`` every ``period_s`` (the attacker's pace, not something
    a test asserts on) until :meth:`stop`; what the target sends back is counted in ``received``.
    """

    def __init__(self, dest: tuple[str, int], messages: Sequence[mavlink2.MAVLink_message], period_s: float = 0.01,
                 system: int = 1, component: int = 1) -> None:  # fmt: skip
        self.dest = dest
        self.mav = mavlink2.MAVLink(None, srcSystem=system, srcComponent=component)
        self.messages = list(messages)
        self.period_s = period_s
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.settimeout(period_s)
        self.sent = 0
        self.received = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="attacker", daemon=True)

    def _run(self) -> None:
        while not self._stop.is_set():
            for msg in self.messages:
                self.sock.sendto(msg.pack(self.mav), self.dest)
                self.mav.seq = (self.mav.seq + 1) & 0xFF
                self.sent += 1
            try:  # doubles as the pace: wait up to period_s for anything sent back to us
                if self.sock.recv(65535):
                    self.received += 1
            except (TimeoutError, ConnectionRefusedError):
                pass

    def start(self) -> Attacker:
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(5.0)
        self.sock.close()


@contextmanager
def attacking(dest: tuple[str, int], messages: Sequence[mavlink2.MAVLink_message], **kw: object) -> Iterator[Attacker]:
    attacker = Attacker(dest, messages, **kw).start()  # type: ignore[arg-type]
    try:
        yield attacker
    finally:
        attacker.stop()
