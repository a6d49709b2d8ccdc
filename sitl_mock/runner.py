"""Run the mock next to a client: in a background thread, or in a subprocess (true parallelism).

    with run_in_thread(config) as mock:          # mock.ports, mock.truth, mock.inject_takeover(...)
        ...
    handle = spawn(config); handle.ports; handle.stop()   # python -m sitl_mock in a subprocess
"""

from __future__ import annotations

import asyncio
import json
import subprocess
import sys
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any, TypeVar

from sitl_mock.config import MockConfig
from sitl_mock.dynamics import VehicleState
from sitl_mock.server import MockAutopilot, Ports

T = TypeVar("T")


class ThreadedMock:
    """A :class:`MockAutopilot` running on its own event loop in a daemon thread."""

    def __init__(self, config: MockConfig) -> None:
        self.config = config
        self.mock = MockAutopilot(config)
        self._loop = asyncio.new_event_loop()
        self._ready = threading.Event()
        self._error: BaseException | None = None
        self._stop: asyncio.Event | None = None
        self._thread = threading.Thread(target=self._run, name="sitl-mock", daemon=True)

    def _run(self) -> None:
        asyncio.set_event_loop(self._loop)
        try:
            self._loop.run_until_complete(self._main())
        except BaseException as exc:  # reported to the starting thread  # noqa: BLE001
            self._error = exc
            self._ready.set()
        finally:
            self._loop.close()

    async def _main(self) -> None:
        self._stop = asyncio.Event()
        async with self.mock:
            self._ready.set()
            await self._stop.wait()

    def start(self, timeout_s: float = 10.0) -> ThreadedMock:
        self._thread.start()
        if not self._ready.wait(timeout_s):
            raise TimeoutError("sitl-mock thread did not start")
        if self._error is not None:
            raise self._error
        return self

    def stop(self) -> None:
        if self._thread.is_alive() and self._stop is not None:
            self._loop.call_soon_threadsafe(self._stop.set)
            self._thread.join(10.0)

    @property
    def ports(self) -> Ports:
        return self.mock.ports

    @property
    def truth(self) -> VehicleState:
        return self.mock.truth

    @property
    def time_s(self) -> float:
        return self.mock.time_s

    def call(self, fn: Callable[[MockAutopilot], T], timeout_s: float = 5.0) -> T:
        """Run ``fn(mock)`` on the mock's loop and return its result (thread-safe access)."""

        async def run() -> T:
            return fn(self.mock)

        return asyncio.run_coroutine_threadsafe(run(), self._loop).result(timeout_s)

    def inject_takeover(self, mode: str | None = None) -> None:
        self.call(lambda m: m.inject_takeover(mode))

    def inject_estimator_reset(self, delta_ned_m: tuple[float, float, float]) -> None:
        self.call(lambda m: m.inject_estimator_reset(delta_ned_m))

    def inject_gust(self, velocity_ned_m_s: tuple[float, float, float], duration_s: float = 1.0) -> None:
        self.call(lambda m: m.inject_gust(velocity_ned_m_s, duration_s))


@contextmanager
def run_in_thread(config: MockConfig) -> Iterator[ThreadedMock]:
    """Context manager: the mock runs in a background thread while the body runs."""
    handle = ThreadedMock(config).start()
    try:
        yield handle
    finally:
        handle.stop()


class SpawnedMock:
    """``python -m sitl_mock`` in a subprocess; ``ports`` as it reported them."""

    def __init__(self, process: subprocess.Popen[str], ports: Ports) -> None:
        self.process = process
        self.ports = ports

    def stop(self, timeout_s: float = 10.0) -> int:
        if self.process.poll() is None:
            self.process.terminate()
            try:
                self.process.wait(timeout_s)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait()
        if self.process.stdout is not None:
            self.process.stdout.close()
        return self.process.returncode

    def __enter__(self) -> SpawnedMock:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.stop()


def spawn(config: MockConfig, extra_args: list[str] | None = None) -> SpawnedMock:
    """Start the mock in a subprocess and wait until it has bound its ports."""
    from sitl_mock.argv import config_to_args

    config.validate()
    cmd = [sys.executable, "-m", "sitl_mock", *config_to_args(config), "--print-ports", *(extra_args or [])]
    process = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    assert process.stdout is not None
    line = process.stdout.readline()
    if not line:
        process.wait()
        raise RuntimeError(f"sitl-mock subprocess exited with code {process.returncode}: {' '.join(cmd)}")
    ports = json.loads(line)
    return SpawnedMock(process, Ports(ports["udp"], ports["tcp"]))
