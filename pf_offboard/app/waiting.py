"""Waiting on conditions of the flight without polling the wall clock in a busy loop.

Every event that may change a condition (a HEARTBEAT, a COMMAND_ACK, a PARAM_VALUE, a state
sample, a phase change) calls :meth:`Waiter.notify`; waits re-check their predicate then (and at
least every 0.1 s). A stop request (Ctrl-C, leaving the API's ``async with``) and a flight that
is ending another way cut *interruptible* waits short.
"""

from __future__ import annotations

import asyncio
from collections.abc import Callable


class Waiter:
    """``changed`` (set on every event), ``stop`` (a stop was requested), and timed waits."""

    def __init__(self, clock: Callable[[], float], ending: Callable[[], bool]) -> None:
        self.clock = clock
        self.ending = ending  # the flight is ending another way (safing, taken over, failed)
        self.changed = asyncio.Event()
        self.stop = asyncio.Event()

    def notify(self) -> None:
        self.changed.set()

    async def until(self, predicate: Callable[[], bool], timeout_s: float, interruptible: bool = True) -> bool:
        """Until ``predicate()`` or the timeout; an ``interruptible`` wait also ends on a stop
        request and when the flight is ending another way."""
        deadline = self.clock() + timeout_s
        while not predicate():
            remaining = deadline - self.clock()
            if remaining <= 0 or (interruptible and (self.stop.is_set() or self.ending())):
                return predicate()
            self.changed.clear()
            try:
                await asyncio.wait_for(self.changed.wait(), min(remaining, 0.1))
            except TimeoutError:
                pass
        return True
