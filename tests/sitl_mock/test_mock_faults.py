"""Fault injection does what it says: loss %, duplicates, CRC-breaking corruption, latency, blackout."""

from __future__ import annotations

import asyncio

import numpy as np
import pytest
from pymavlink.dialects.v20 import common as mavlink

from sitl_mock.config import FaultConfig, MockConfig, SpawnSpec
from sitl_mock.faults import FaultInjector
from sitl_mock.server import MockAutopilot, encode, new_mavlink
from sitl_mock.testing import UdpClient

N = 20000


def _frames(n: int) -> list[bytes]:
    mav = new_mavlink()
    return [encode(mav, mavlink.MAVLink_attitude_message(i, 0.1, 0.2, 0.3, 0, 0, 0)) for i in range(n)]


def test_loss_rate_matches_setting() -> None:
    injector = FaultInjector(FaultConfig(loss=0.2), np.random.default_rng(1))
    sent = sum(len(injector.outgoing(f, 0.0)) for f in _frames(N))
    assert sent / N == pytest.approx(0.8, abs=0.015)
    dropped = sum(injector.drop_incoming() for _ in range(N))
    assert dropped / N == pytest.approx(0.2, abs=0.015)


def test_loss_from_offboard_starts_with_the_mode() -> None:
    """``loss_from_offboard``: nothing is lost, either way, until the autopilot enters OFFBOARD /
    GUIDED (start_windows); from then on the configured rate."""
    injector = FaultInjector(FaultConfig(loss=0.5, loss_from_offboard=True), np.random.default_rng(3))
    assert sum(len(injector.outgoing(f, 0.0)) for f in _frames(200)) == 200
    assert not any(injector.drop_incoming() for _ in range(200))
    injector.start_windows(1.0)
    sent = sum(len(injector.outgoing(f, 1.0)) for f in _frames(N))
    assert sent / N == pytest.approx(0.5, abs=0.02)
    assert sum(injector.drop_incoming() for _ in range(N)) / N == pytest.approx(0.5, abs=0.02)


def test_duplicates() -> None:
    injector = FaultInjector(FaultConfig(duplicate=0.1), np.random.default_rng(2))
    sent = sum(len(injector.outgoing(f, 0.0)) for f in _frames(N))
    assert sent / N == pytest.approx(1.1, abs=0.015)


def test_corruption_is_caught_by_the_crc() -> None:
    injector = FaultInjector(FaultConfig(corrupt=0.3), np.random.default_rng(3))
    parser = new_mavlink()
    good = bad = 0
    for frame in _frames(2000):
        for _, data in injector.outgoing(frame, 0.0):
            for msg in parser.parse_buffer(data) or []:
                if msg.get_type() == "BAD_DATA":
                    bad += 1
                else:
                    good += 1
    assert good / 2000 == pytest.approx(0.7, abs=0.04)
    assert bad > 0 and injector.corrupted == 2000 - good


def test_latency_jitter_and_blackout() -> None:
    injector = FaultInjector(FaultConfig(latency_s=0.05, jitter_s=0.02, blackout_s=(1.0, 2.0)), np.random.default_rng(4))
    frame = _frames(1)[0]
    releases = [injector.outgoing(frame, 0.5)[0][0] for _ in range(1000)]
    assert min(releases) >= 0.55 and max(releases) < 0.57 and np.std(releases) > 0.004
    assert injector.outgoing(frame, 1.5) == [] and injector.outgoing(frame, 2.0) != []


def test_fault_config_validation() -> None:
    with pytest.raises(ValueError, match="faults.loss"):
        FaultConfig(loss=1.5).validate()
    with pytest.raises(ValueError, match="faults.blackout_s"):
        FaultConfig(blackout_s=(3.0, 1.0)).validate()


@pytest.mark.integration
def test_loss_and_corruption_over_udp() -> None:
    """At 10x speed, ATTITUDE (100 Hz) arrives at ~(1 - loss) of its rate; corrupted ones fail CRC."""

    async def scenario() -> tuple[int, int, float]:
        config = MockConfig(vehicle="fast", udp_local_port=0, udp_remote=None, speed=10.0, spawn=SpawnSpec("hover", (0, 0, -5)),
                            faults=FaultConfig(loss=0.3, corrupt=0.1))
        async with MockAutopilot(config) as mock:
            loop = asyncio.get_running_loop()

            def client() -> tuple[int, int, float]:
                with UdpClient(mock.ports.udp) as c:
                    # Register (repeat: the first datagrams may be lost) and count over 3 s of sim time.
                    for _ in range(5):
                        c.send(mavlink.MAVLink_heartbeat_message(6, 8, 0, 0, 0, 3))
                    times = []
                    while not times or times[-1] < 4000:
                        times += [m.time_boot_ms for m in c.recv() if m.get_type() == "ATTITUDE"]
                    window = [t for t in times if 1000 <= t < 4000]
                    return len(window), c.bad, 3.0

            return await loop.run_in_executor(None, client)

    count, bad, seconds = asyncio.run(scenario())
    # Delivered: not lost (0.7) and not corrupted (0.9) → 0.63 of 100 Hz.
    assert count / (100 * seconds) == pytest.approx(0.63, abs=0.08)
    assert bad > 0
