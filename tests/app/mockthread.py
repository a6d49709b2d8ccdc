"""Run the real sitl_mock MockAutopilot (real loopback sockets) on its own event loop thread."""

from __future__ import annotations

import asyncio
import threading
from collections.abc import Callable
from typing import Any

from sitl_mock.config import MockConfig
from sitl_mock.server import MockAutopilot


class MockThread:
    """``with MockThread(config) as mock: mock.ports.udp ...``; ``mock.call(fn)`` runs ``fn(autopilot)``
    on the mock's loop and returns its result."""

    def __init__(self, config: MockConfig) -> None:
        self.config = config
        self.mock: MockAutopilot | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._ready = threading.Event()
        self._thread = threading.Thread(target=self._run, name="sitl-mock", daemon=True)
        self._error: BaseException | None = None

    def _run(self) -> None:
        loop = asyncio.new_event_loop()
        self._loop = loop
        try:
            self.mock = MockAutopilot(self.config)
            loop.run_until_complete(self.mock.start())
        except BaseException as exc:  # reported to the test thread
            self._error = exc
            self._ready.set()
            return
        self._ready.set()
        loop.run_forever()
        loop.run_until_complete(self.mock.stop())
        loop.close()

    def __enter__(self) -> MockThread:
        self._thread.start()
        if not self._ready.wait(10.0):
            raise RuntimeError("sitl-mock did not start within 10 s")
        if self._error is not None:
            raise self._error
        return self

    def __exit__(self, *exc: object) -> None:
        assert self._loop is not None
        self._loop.call_soon_threadsafe(self._loop.stop)
        self._thread.join(10.0)

    @property
    def ports(self) -> Any:
        assert self.mock is not None
        return self.mock.ports

    def call(self, fn: Callable[[MockAutopilot], Any], timeout_s: float = 5.0) -> Any:
        assert self._loop is not None and self.mock is not None

        async def run() -> Any:
            return fn(self.mock)

        return asyncio.run_coroutine_threadsafe(run(), self._loop).result(timeout_s)
