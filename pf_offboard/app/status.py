"""The status display: one line of progress (a terminal: rewritten in place 5 times a second;
a file or pipe: one line a second), and the messages a flight prints on the same stream."""

from __future__ import annotations

import asyncio
from collections.abc import Callable
from typing import Any, TextIO


def status_text(phase: str, mode: str, armed: bool, step: Any, laps: float, rate_hz: float) -> str:
    """The status line. ``step``: the last :class:`~pf_offboard.app.pipeline.Step` (or None)."""
    head = f"[{phase}] {mode} {'armed' if armed else 'disarmed'}"
    if step is None or step.command is None:
        return f"{head}  rate {rate_hz:5.0f} Hz"
    st = step.command.state
    return (
        f"{head}  η1 {st.eta1:7.2f} m  η2 {st.eta2:+5.2f} m/s  ξ1 {st.xi1:+6.3f} m  φ1 {st.phi1:+6.3f} m  "
        f"e {step.command.cross_track_m:6.3f} m  laps {laps:4.2f}  rate {rate_hz:5.0f} Hz"
    )


class StatusDisplay:
    """Writes to ``stream``; ``enabled`` False (``--quiet``) keeps only :meth:`note` lines."""

    def __init__(self, stream: TextIO, enabled: bool, clock: Callable[[], float]) -> None:
        self.stream = stream
        self.enabled = enabled
        self.clock = clock
        self.samples = 0  # fresh state samples since the last status period
        self.loop_rate_hz = 0.0

    def count_sample(self) -> None:
        self.samples += 1

    def note(self, text: str) -> None:
        """One line on the status stream even with --quiet (facts the user must know)."""
        self.stream.write(("\r\x1b[K" if self.stream.isatty() else "") + text + "\n")
        self.stream.flush()

    def say(self, text: str) -> None:
        """One line, unless quiet."""
        if self.enabled:
            self.note(text)

    async def run(self, text: Callable[[], str], running: Callable[[], bool]) -> None:
        """Update the loop rate and show ``text()`` every period while ``running()``."""
        tty = self.stream.isatty()
        period = 0.2 if tty else 1.0
        last = self.clock()
        try:
            while running():
                await asyncio.sleep(period)
                now = self.clock()
                self.loop_rate_hz, self.samples, last = self.samples / max(now - last, 1e-9), 0, now
                if self.enabled:
                    line = text()
                    self.stream.write(f"\r{line}\x1b[K" if tty else line + "\n")
                    self.stream.flush()
        finally:  # also when cancelled at the end of the flight
            if self.enabled and tty:
                self.stream.write("\n")
