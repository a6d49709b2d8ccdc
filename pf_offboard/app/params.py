"""Autopilot parameters over MAVLink: PARAM_VALUE decoding (PX4 packs INT32 bytewise, ArduPilot
casts) and confirmed reads / writes (PARAM_REQUEST_READ / PARAM_SET, re-sent every 0.5 s)."""

from __future__ import annotations

import struct
from typing import Any

from pymavlink.dialects.v20 import common as mavlink2

from pf_offboard.app.waiting import Waiter
from pf_offboard.errors import LinkError


def param_value_decode(value: float, param_type: int, bytewise: bool) -> float:
    """A PARAM_VALUE's value: PX4 packs INT32 bytewise into the float, ArduPilot casts."""
    if bytewise and param_type in (mavlink2.MAV_PARAM_TYPE_INT32, mavlink2.MAV_PARAM_TYPE_UINT32):
        return float(struct.unpack("<i", struct.pack("<f", value))[0])
    return float(value)


def param_value_encode(value: float, param_type: int, bytewise: bool) -> float:
    """Inverse of :func:`param_value_decode` for PARAM_SET."""
    if bytewise and param_type in (mavlink2.MAV_PARAM_TYPE_INT32, mavlink2.MAV_PARAM_TYPE_UINT32):
        return float(struct.unpack("<f", struct.pack("<i", int(value)))[0])
    return float(value)


class Parameters:
    """Reads and writes the target's parameters; :meth:`on_param_value` is fed every PARAM_VALUE."""

    def __init__(self, link: Any, waiter: Waiter, bytewise: bool, timeout_s: float) -> None:
        self.link = link
        self.waiter = waiter
        self.bytewise = bytewise
        self.timeout_s = timeout_s
        self.values: dict[str, float] = {}

    def on_param_value(self, msg: Any) -> None:
        pid = msg.param_id if isinstance(msg.param_id, str) else msg.param_id.decode()
        self.values[pid.rstrip("\x00")] = param_value_decode(msg.param_value, msg.param_type, self.bytewise)
        self.waiter.notify()

    async def read(self, name: str) -> float:
        t = self.link.target
        clock = self.waiter.clock
        deadline = clock() + self.timeout_s
        self.values.pop(name, None)
        while name not in self.values:
            self.link.send(mavlink2.MAVLink_param_request_read_message(t.system, t.component, name.encode(), -1))
            await self.waiter.until(lambda: name in self.values, 0.5)
            if clock() > deadline and name not in self.values:
                raise LinkError(f"parameter {name}: no PARAM_VALUE within {self.timeout_s:g} s")
        return self.values[name]

    async def write(self, name: str, value: float, param_type: int) -> float:
        t = self.link.target
        clock = self.waiter.clock
        deadline = clock() + self.timeout_s
        while True:
            self.values.pop(name, None)
            self.link.send(
                mavlink2.MAVLink_param_set_message(t.system, t.component, name.encode(), param_value_encode(value, param_type, self.bytewise), param_type)
            )
            await self.waiter.until(lambda: name in self.values, 0.5)
            if name in self.values and self.values[name] == value:
                return value
            if clock() > deadline:
                got = self.values.get(name)
                raise LinkError(f"parameter {name}: set to {value:g} not confirmed (PARAM_VALUE {got})")
