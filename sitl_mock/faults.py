"""Link faults applied to encoded datagrams: loss, duplication, corruption, latency, blackout.

Draws come from the mock's seeded Generator, a fixed number per datagram for each enabled
fault, so runs with the same seed and the same traffic are identical.
"""

from __future__ import annotations

import numpy as np

from sitl_mock.config import FaultConfig

# MAVLink 2 header is 10 bytes; corrupting a byte after it (payload or CRC) makes the CRC fail.
_HEADER_LEN = 10


class FaultInjector:
    """Decides the fate of each datagram. Times are simulated seconds."""

    def __init__(self, config: FaultConfig, rng: np.random.Generator) -> None:
        self.config = config
        self.rng = rng
        self.dropped_out = 0
        self.dropped_in = 0
        self.duplicated = 0
        self.corrupted = 0
        self.reordered = 0  # ATTITUDE_QUATERNION samples sent after a newer one
        self._held: dict[object, bytes] = {}  # per peer: the attitude sample held back
        # where the blackout / mute windows count from (None: not yet, see windows_from_offboard)
        self.origin_s: float | None = None if config.windows_from_offboard else 0.0
        self._offboard_seen = False

    def start_windows(self, now_s: float) -> None:
        """The autopilot entered OFFBOARD / GUIDED: relative windows count from now (once), and
        ``loss_from_offboard`` loss starts."""
        self._offboard_seen = True
        if self.origin_s is None:
            self.origin_s = now_s

    def _lossy(self) -> bool:
        return self.config.loss > 0.0 and (self._offboard_seen or not self.config.loss_from_offboard)

    def _in(self, window: tuple[float, float] | None, now_s: float) -> bool:
        if window is None or self.origin_s is None:
            return False
        return window[0] <= now_s - self.origin_s < window[1]

    def in_blackout(self, now_s: float) -> bool:
        return self._in(self.config.blackout_s, now_s)

    def heartbeat_muted(self, data: bytes, now_s: float) -> bool:
        """A HEARTBEAT (MAVLink 2 message id 0, bytes 7..9 of the frame) inside the mute window."""
        if not self._in(self.config.heartbeat_mute_s, now_s):
            return False
        return len(data) > 10 and data[0] == 0xFD and data[7:10] == b"\x00\x00\x00"

    def outgoing(self, data: bytes, now_s: float) -> list[tuple[float, bytes]]:
        """(release time, bytes) for each copy to send; empty if the datagram is lost."""
        cfg = self.config
        if self.in_blackout(now_s) or self.heartbeat_muted(data, now_s):
            self.dropped_out += 1
            return []
        if self._lossy() and self.rng.random() < cfg.loss:
            self.dropped_out += 1
            return []
        if cfg.corrupt > 0.0:
            hit, where = self.rng.random(), self.rng.random()
            if hit < cfg.corrupt and len(data) > _HEADER_LEN:
                index = _HEADER_LEN + int(where * (len(data) - _HEADER_LEN))
                buf = bytearray(data)
                buf[index] ^= 0xFF
                data = bytes(buf)
                self.corrupted += 1
        copies = 1
        if cfg.duplicate > 0.0 and self.rng.random() < cfg.duplicate:
            copies = 2
            self.duplicated += 1
        delay = cfg.latency_s
        if cfg.jitter_s > 0.0:
            delay += cfg.jitter_s * self.rng.random()
        return [(now_s + delay, data)] * copies

    def reorder_attitude(self, peer: object, data: bytes) -> list[bytes]:
        """What to send now for one encoded ATTITUDE_QUATERNION to ``peer``, in order: nothing (held
        back, with probability ``attitude_reorder``), or it followed by the one held before it."""
        held = self._held.pop(peer, None)
        if held is None:
            if self.rng.random() < self.config.attitude_reorder:
                self._held[peer] = data
                return []
            return [data]
        self.reordered += 1
        return [data, held]

    def drop_incoming(self) -> bool:
        if self._lossy() and self.rng.random() < self.config.loss:
            self.dropped_in += 1
            return True
        return False
