"""MAVLink link: endpoint parsing, opening through pymavlink's mavutil, an event-driven reader.

No busy spin: the reader is ``loop.add_reader`` on the connection's file descriptor (UDP, TCP
and serial all have one on POSIX), so a received datagram is decoded and handed to the
application in the same event-loop callback. Sending is a non-blocking socket write.
"""

from __future__ import annotations

import asyncio
import os
import re
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from pf_offboard.errors import InputError, LinkError

# MAVLink 2 framing (ODOMETRY and others have ids > 255): must be chosen before mavutil is imported.
os.environ.setdefault("MAVLINK20", "1")

from pymavlink import mavutil  # noqa: E402  (after the environment switch above)

if getattr(mavutil.mavlink, "WIRE_PROTOCOL_VERSION", "1.0") != "2.0":  # imported earlier without it
    os.environ["MAVLINK20"] = "1"
    mavutil.set_dialect(mavutil.current_dialect)

MAV_COMP_ID_ONBOARD_COMPUTER = 191
MAV_TYPE_ONBOARD_CONTROLLER = 18
MAV_TYPE_GCS = 6
MAV_AUTOPILOT_INVALID = 8

_HOST_RE = re.compile(r"^[A-Za-z0-9.\-]+$")
KINDS = ("udpin", "udpout", "tcp", "serial")


@dataclass(frozen=True)
class Endpoint:
    """A parsed ``--connect`` endpoint. ``address`` is host (udp/tcp) or device path (serial);
    ``port`` is the UDP/TCP port or the serial baud rate."""

    kind: str
    address: str
    port: int

    def mavutil_url(self) -> str:
        """The string pymavlink's ``mavlink_connection`` understands."""
        if self.kind == "serial":
            return self.address
        return f"{self.kind}:{self.address}:{self.port}"

    def __str__(self) -> str:
        return f"{self.kind}:{self.address}:{self.port}"


def parse_endpoint(text: str) -> Endpoint:
    """Parse ``udpin:HOST:PORT``, ``udpout:HOST:PORT``, ``tcp:HOST:PORT`` or ``serial:DEVICE:BAUD``.

    Raises :class:`InputError` naming ``--connect`` and what is wrong.
    """
    field = "--connect"
    if not isinstance(text, str) or ":" not in text:
        raise InputError(field, f"{text!r} is not KIND:ADDRESS:PORT (KIND one of {', '.join(KINDS)})")
    kind, _, rest = text.partition(":")
    if kind not in KINDS:
        raise InputError(field, f"unknown endpoint kind {kind!r} in {text!r}; use one of {', '.join(KINDS)}")
    address, sep, number = rest.rpartition(":")
    if not sep or not address or not number:
        what = "DEVICE:BAUD" if kind == "serial" else "HOST:PORT"
        raise InputError(field, f"{text!r}: expected {kind}:{what}")
    if not number.isdigit():
        what = "baud rate" if kind == "serial" else "port"
        raise InputError(field, f"{text!r}: {what} {number!r} is not a positive integer")
    value = int(number)
    if kind == "serial":
        if value <= 0:
            raise InputError(field, f"{text!r}: baud rate must be positive")
        return Endpoint(kind, address, value)
    if not 1 <= value <= 65535:
        raise InputError(field, f"{text!r}: port {value} is outside 1..65535")
    if not _HOST_RE.match(address):
        raise InputError(field, f"{text!r}: host {address!r} is not a host name or IPv4 address")
    return Endpoint(kind, address, value)


@dataclass(frozen=True)
class VehicleId:
    """The system/component the app talks to, with the HEARTBEAT fields that identify it."""

    system: int
    component: int
    autopilot: int
    vehicle_type: int


def is_vehicle_heartbeat(msg: Any) -> bool:
    """A HEARTBEAT from an autopilot (not a GCS, not another companion computer)."""
    return (
        msg.get_type() == "HEARTBEAT"
        and msg.autopilot != MAV_AUTOPILOT_INVALID
        and msg.type not in (MAV_TYPE_GCS, MAV_TYPE_ONBOARD_CONTROLLER)
    )


class Link:
    """An open MAVLink connection. Create with :meth:`open`; close with :meth:`close`.

    ``on_message`` (set by the caller) receives every decoded message from the target system;
    ``on_sent`` / ``on_received`` (optional) see every frame for the telemetry log.
    """

    def __init__(self, endpoint: Endpoint, conn: Any) -> None:
        self.endpoint = endpoint
        self._conn = conn
        self.target: VehicleId | None = None
        self.on_received: Callable[[Any], None] | None = None
        self.on_sent: Callable[[Any], None] | None = None
        self._handler: Callable[[Any], None] | None = None
        self._reading = False
        self.error: LinkError | None = None
        self.first_heartbeat: Any = None  # the HEARTBEAT that identified the target

    @classmethod
    def open(cls, endpoint: Endpoint, source_system: int = 1) -> Link:
        """Open the endpoint (binds / connects; no traffic yet). Raises :class:`LinkError`."""
        try:
            conn = mavutil.mavlink_connection(
                endpoint.mavutil_url(),
                baud=endpoint.port if endpoint.kind == "serial" else 115200,
                source_system=source_system,
                source_component=MAV_COMP_ID_ONBOARD_COMPUTER,
                autoreconnect=False,
                robust_parsing=True,
            )
        except ImportError as exc:  # pymavlink opens serial ports with pyserial, an optional package
            raise LinkError(f"cannot open {endpoint}: {exc.name or 'serial'} is not installed (pip install pyserial)") from exc
        except Exception as exc:  # socket / serial errors come in many types
            raise LinkError(f"cannot open {endpoint}: {exc}") from exc
        fd = getattr(conn, "fd", None)
        if fd is None:
            conn.close()
            raise LinkError(f"{endpoint}: connection has no file descriptor to wait on")
        return cls(endpoint, conn)

    # ------------------------------------------------------------------ receiving
    def start_reading(self, handler: Callable[[Any], None]) -> None:
        """Call ``handler(msg)`` from the event loop for every message from the target."""
        self._handler = handler
        if not self._reading:
            asyncio.get_running_loop().add_reader(self._conn.fd, self._drain)
            self._reading = True

    def stop_reading(self) -> None:
        if self._reading:
            try:
                asyncio.get_running_loop().remove_reader(self._conn.fd)
            except RuntimeError:  # loop already closed
                pass
            self._reading = False

    def _drain(self) -> None:
        """Decode everything that is waiting; never blocks."""
        while True:
            try:
                msg = self._conn.recv_msg()
            except (ConnectionError, OSError) as exc:
                self._handler_error(exc)
                return
            if msg is None:
                return
            if msg.get_type() == "BAD_DATA":
                continue
            if self.on_received is not None:
                self.on_received(msg)
            if self.target is not None and msg.get_srcSystem() != self.target.system:
                continue  # other systems on a shared link are not ours to follow
            if self._handler is not None:
                self._handler(msg)

    def _handler_error(self, exc: BaseException) -> None:
        self.stop_reading()
        self.error = LinkError(f"{self.endpoint}: link failed: {exc}")

    async def wait_heartbeat(self, timeout_s: float, target_system: int | None = None) -> VehicleId:
        """Wait for an autopilot HEARTBEAT (from ``target_system`` if given); :class:`LinkError` on timeout.

        We announce ourselves with our own HEARTBEAT every second meanwhile, because a UDP
        autopilot (``udpout``) only learns our address from what we send.
        """
        loop = asyncio.get_running_loop()
        found: asyncio.Future[VehicleId] = loop.create_future()

        def handler(msg: Any) -> None:
            if found.done() or not is_vehicle_heartbeat(msg):
                return
            if target_system is not None and msg.get_srcSystem() != target_system:
                return
            self.first_heartbeat = msg
            found.set_result(VehicleId(msg.get_srcSystem(), msg.get_srcComponent(), msg.autopilot, msg.type))

        self.start_reading(handler)
        deadline = loop.time() + timeout_s
        try:
            while not found.done():
                self.send_heartbeat()
                remaining = deadline - loop.time()
                if remaining <= 0:
                    break
                try:
                    await asyncio.wait_for(asyncio.shield(found), timeout=min(1.0, remaining))
                except TimeoutError:
                    pass
                if self.error is not None:
                    raise self.error
        finally:
            self.stop_reading()
        if not found.done():
            raise LinkError(f"no HEARTBEAT from an autopilot on {self.endpoint} within {timeout_s:g} s")
        self.target = found.result()
        return self.target

    # ------------------------------------------------------------------ sending
    def set_source_system(self, system: int) -> None:
        """Our system id in outgoing frames (a companion computer shares its vehicle's)."""
        self._conn.mav.srcSystem = system

    def send(self, msg: Any) -> None:
        """Pack and send one message (our system/component ids, next sequence number)."""
        try:
            self._conn.mav.send(msg)
        except OSError as exc:
            raise LinkError(f"{self.endpoint}: send failed: {exc}") from exc
        if self.on_sent is not None:
            self.on_sent(msg)

    def send_heartbeat(self) -> None:
        """Our 1 Hz HEARTBEAT: an onboard controller, not an autopilot."""
        self.send(
            self._conn.mav.heartbeat_encode(
                MAV_TYPE_ONBOARD_CONTROLLER, MAV_AUTOPILOT_INVALID, 0, 0, 4  # MAV_STATE_ACTIVE
            )
        )

    def close(self) -> None:
        self.stop_reading()
        try:
            self._conn.close()
        except OSError:
            pass
