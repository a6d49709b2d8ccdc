"""MAVLink link: endpoint parsing, opening through pymavlink's mavutil, an event-driven reader.

No busy spin: the reader is ``loop.add_reader`` on the connection's file descriptor (UDP, TCP
and serial all have one on POSIX), so a received datagram is decoded and handed to the
application in the same event-loop callback. Sending is a non-blocking socket write.
"""

from __future__ import annotations

import asyncio
import collections
import dataclasses
import os
import re
import socket
import struct
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from pf_offboard.app.controllers import SETPOINT_MESSAGES
from pf_offboard.app.signing import verify_signature_first
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
KINDS = ("udpin", "udpout", "tcp", "tcpin", "serial")
# how users write endpoints (MAVSDK URLs, pymavlink / MAVProxy strings) -> our kinds; see docs/api.md
_URL_SCHEMES = {"udp": "udpin", "udpin": "udpin", "udpout": "udpout", "tcp": "tcp", "tcpout": "tcp", "tcpin": "tcpin", "serial": "serial"}
_PREFIXES = {"udp": "udpin", "udpin": "udpin", "udpout": "udpout", "tcp": "tcp", "tcpin": "tcpin", "serial": "serial"}
DEFAULT_BAUD = 115200
FORMS = ("udp://:14540 (listen), udpout://HOST:PORT, tcp://HOST:PORT, serial:///dev/ttyACM0:921600 (MAVSDK); "
         "udpin:HOST:PORT, udpout:HOST:PORT, tcp:HOST:PORT, tcpin:HOST:PORT, /dev/ttyACM0,921600 (pymavlink / MAVProxy)")  # fmt: skip


@dataclass(frozen=True)
class Endpoint:
    """A parsed ``--connect`` endpoint. ``kind``: udpin (listen) | udpout (send to) | tcp (connect)
    | tcpin (accept) | serial; ``address`` is host (udp/tcp) or device path (serial); ``port`` is
    the UDP/TCP port or the serial baud rate."""

    kind: str
    address: str
    port: int

    def check_local(self) -> None:
        """Bad input found before opening (InputError naming --connect): a serial device that does
        not exist or is not a character device (a regular file, a directory, /dev/null is one: it
        is opened and fails then)."""
        if self.kind != "serial":
            return
        import stat

        try:
            st = os.stat(self.address)
        except (OSError, ValueError) as exc:
            raise InputError("--connect", f"serial device {_clip(self.address)}: {getattr(exc, 'strerror', None) or exc}") from None
        if not stat.S_ISCHR(st.st_mode):
            raise InputError("--connect", f"serial device {_clip(self.address)}: not a character device")
        try:  # a character device that is not a terminal (/dev/zero, /dev/null) is no serial port
            fd = os.open(self.address, os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_NOCTTY", 0))
        except OSError:
            return  # busy or not permitted: opening it for real reports that (a link error)
        try:
            if not os.isatty(fd):
                raise InputError("--connect", f"serial device {_clip(self.address)}: not a serial port (not a terminal device)")
        finally:
            os.close(fd)

    def mavutil_url(self) -> str:
        """The string pymavlink's ``mavlink_connection`` understands."""
        if self.kind == "serial":
            return self.address
        return f"{self.kind}:{self.address}:{self.port}"

    def __str__(self) -> str:
        return f"{self.kind}:{self.address}:{self.port}"


def parse_endpoint(text: str) -> Endpoint:
    """Parse an endpoint as users write it. Our own form is ``KIND:ADDRESS:PORT`` (``udpin``,
    ``udpout``, ``tcp``, ``tcpin``, ``serial:DEVICE:BAUD``); MAVSDK URLs (``udp://[HOST]:PORT``
    listens, ``udpin://``, ``udpout://``, ``tcp://``, ``tcpin://``, ``serial://DEVICE[:BAUD]``) and
    pymavlink / MAVProxy strings (``udp:HOST:PORT`` listens, ``/dev/ttyACM0,921600``) map onto it.

    Raises :class:`InputError` naming ``--connect``, what is wrong and the forms that work.
    """
    field = "--connect"
    if not isinstance(text, str) or not text.strip():
        raise InputError(field, f"{text!r} is not KIND:ADDRESS:PORT (KIND one of {', '.join(KINDS)}); forms: {FORMS}")
    text = text.strip()
    if "://" in text:
        return _parse_url(text, field)
    if text.startswith("/") or re.match(r"^COM\d+([,:]|$)", text, re.IGNORECASE):
        return _serial(text, text, re.split(r"[,:]", text, maxsplit=1)[0] if not text.startswith("/") else text, field)
    if ":" not in text:
        raise InputError(field, f"{text!r} is not KIND:ADDRESS:PORT (KIND one of {', '.join(KINDS)}); forms: {FORMS}")
    prefix, _, rest = text.partition(":")
    kind = _PREFIXES.get(prefix.lower())
    if kind is None:
        raise InputError(field, f"unknown endpoint kind {prefix!r} in {text!r}; use one of {', '.join(KINDS)} ({FORMS})")
    if kind == "serial":
        device, sep, number = rest.rpartition(":")
        if not sep or not device or not number:
            raise InputError(field, f"{text!r}: expected serial:DEVICE:BAUD (e.g. serial:/dev/ttyACM0:921600)")
        return _baud(text, device, number, field)
    return _host_port(text, kind, rest, f"{prefix}:HOST:PORT", field)


def _parse_url(text: str, field: str) -> Endpoint:
    scheme, _, rest = text.partition("://")
    kind = _URL_SCHEMES.get(scheme.lower())
    if kind is None:
        raise InputError(field, f"unknown endpoint scheme {scheme!r} in {text!r}; use {FORMS}")
    if kind == "serial":
        # serial:///dev/ttyACM0:921600 (MAVSDK): the device path, then an optional :BAUD
        return _serial(text, rest, rest, field)
    host, sep, number = rest.rpartition(":")
    if not sep or not number:
        raise InputError(field, f"{text!r}: expected {scheme}://[HOST]:PORT (e.g. {scheme}://:14540 or {scheme}://127.0.0.1:14540)")
    if not host:
        if kind in ("udpout", "tcp"):
            raise InputError(field, f"{text!r}: {scheme}:// needs the HOST to send to, e.g. {scheme}://127.0.0.1:{number}")
        host = "0.0.0.0"  # listen on every interface, as MAVSDK does
    return _host_port(text, kind, f"{host}:{number}", f"{scheme}://[HOST]:PORT", field)


def _serial(text: str, rest: str, device_hint: str, field: str) -> Endpoint:
    """``DEVICE``, ``DEVICE:BAUD`` or ``DEVICE,BAUD`` (MAVProxy)."""
    for sep in (",", ":"):
        device, found, number = rest.rpartition(sep)
        if found and device:
            return _baud(text, device, number, field)
    if not rest:
        raise InputError(field, f"{text!r}: expected a serial device, e.g. serial:///dev/ttyACM0:921600 or /dev/ttyACM0,921600")
    return Endpoint("serial", rest, DEFAULT_BAUD)


def _baud(text: str, device: str, number: str, field: str) -> Endpoint:
    if not number.isdigit():
        raise InputError(field, f"{text!r}: baud rate {number!r} is not a positive integer (e.g. {device}:921600)")
    value = int(number)
    if value <= 0:
        raise InputError(field, f"{text!r}: baud rate must be positive")
    return Endpoint("serial", device, value)


def _host_port(text: str, kind: str, rest: str, form: str, field: str) -> Endpoint:
    address, sep, number = rest.rpartition(":")
    if not sep or not address or not number:
        hint = " (udpin:0.0.0.0:PORT listens on every interface)" if kind == "udpin" else ""
        raise InputError(field, f"{text!r}: expected {form}{hint}")
    if not number.isdigit():
        raise InputError(field, f"{text!r}: port {number!r} is not a positive integer")
    value = int(number)
    if not 1 <= value <= 65535:
        raise InputError(field, f"{text!r}: port {value} is outside 1..65535")
    why = _host_problem(address)
    if why:
        raise InputError(field, f"{_clip(text)}: host {_clip(address)!r} {why}")
    return Endpoint(kind, address, value)


def _clip(text: str, limit: int = 80) -> str:
    return text if len(text) <= limit else f"{text[: limit // 2]}...{text[-limit // 2 :]}"


def _host_problem(host: str) -> str:
    """Why ``host`` is not an IPv4 address or a host name ("" if it is one). Pure: no lookup."""
    if not _HOST_RE.match(host):
        return "is not a host name or IPv4 address"
    parts = host.split(".")
    if all(p.isdigit() for p in parts):  # numeric: must be a dotted-quad IPv4 address
        if len(parts) != 4 or any(len(p) > 3 or int(p) > 255 for p in parts):
            return "is not an IPv4 address (four numbers 0..255)"
        return ""
    labels = host[:-1].split(".") if host.endswith(".") else parts  # a trailing dot: fully qualified
    if len(host) > 253 or any(not 1 <= len(p) <= 63 or p.startswith("-") or p.endswith("-") for p in labels):
        return "is not a valid host name (labels of 1-63 letters, digits or '-', not starting or ending with '-')"
    return ""


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


# At most this many messages are decoded per wake-up of the reader, then the event loop runs the
# other tasks (setpoint keep-alive, stale-state watchdog, HEARTBEAT) before reading on: a
# telemetry flood must not starve them (draining until the socket is empty never yields while a
# sender keeps it full). 50 is a quarter of a 250 Hz second of state; decoding them takes ~1 ms.
MAX_MESSAGES_PER_WAKEUP = 50
# State messages; when one waited in the socket longer than the state timeout it is dropped
# unread (see Link.max_state_age_s): a backlog is never flown.
STATE_MESSAGES = frozenset({"LOCAL_POSITION_NED", "ODOMETRY", "ATTITUDE_QUATERNION"})
# Linux: kernel receive timestamps of UDP datagrams (socket(7)); not exported by Python's socket.
_SO_TIMESTAMPNS = 35
_TIMESPEC = struct.Struct("@ll")
# A datagram was read but yielded no message to handle (another sender, a partial frame).
_SKIPPED: Any = ("skipped",)


@dataclass(frozen=True)
class LinkCounters:
    """What the link refused or skipped (counts of messages, or datagrams for ``foreign_peer``)."""

    foreign_peer: int = 0  # UDP datagrams from an address other than the locked autopilot peer
    not_target: int = 0  # messages from another system / component than the target autopilot
    not_autopilot_heartbeat: int = 0  # HEARTBEATs with the target's ids but not an autopilot's
    bad_signature: int = 0  # unsigned or wrongly signed frames (signing on)
    bad_data: int = 0  # CRC / framing errors
    stale_state: int = 0  # state samples that waited in the socket longer than the state timeout
    foreign_ack: int = 0  # COMMAND_ACKs addressed to another system / component (another GCS's command)
    foreign_setpoint: int = 0  # another controller's setpoints for our autopilot, relayed on our link
    reader_yields: int = 0  # wake-ups that stopped at MAX_MESSAGES_PER_WAKEUP with more waiting

    @property
    def rejected(self) -> int:
        """Messages refused as not coming from the target autopilot (spoofs, other peers)."""
        return self.foreign_peer + self.not_target + self.not_autopilot_heartbeat + self.bad_signature

    def line(self) -> str:
        return (
            f"rejected {self.foreign_peer} from another address, {self.not_target} from another component, "
            f"{self.not_autopilot_heartbeat} non-autopilot HEARTBEATs, {self.bad_signature} badly signed; "
            f"{self.bad_data} corrupt, {self.stale_state} stale state dropped, {self.foreign_ack} ACKs for others ignored, "
            f"{self.foreign_setpoint} setpoints of another controller seen, "
            f"{self.reader_yields} reader yields"
        )


class Link:
    """An open MAVLink connection. Create with :meth:`open`; close with :meth:`close`.

    ``on_message`` (set by the caller) receives every decoded message from the target;
    ``on_sent`` / ``on_received`` (optional) see every frame sent / accepted for the telemetry log.

    Authority: before the target is known, every HEARTBEAT is looked at (to find it). Once it is
    known (:meth:`wait_heartbeat`), only the target autopilot component is believed: messages from
    other systems or components are dropped, a HEARTBEAT with the target's ids that is not an
    autopilot's (a GCS, a companion: what a spoofer sends to fake a mode change) is dropped, and on
    UDP the link is locked to the address the target's HEARTBEAT came from: datagrams from any
    other address are dropped unread and counted, and ``udpin`` answers only that address. With a
    signing key, unsigned or wrongly signed frames are dropped by the parser and counted.
    """

    def __init__(self, endpoint: Endpoint, conn: Any, signing: bool = False) -> None:
        self.endpoint = endpoint
        self._conn = conn
        self.target: VehicleId | None = None
        self.on_received: Callable[[Any], None] | None = None
        self.on_sent: Callable[[Any], None] | None = None
        self._handler: Callable[[Any], None] | None = None
        self._reading = False
        self.error: LinkError | None = None
        self.first_heartbeat: Any = None  # the HEARTBEAT that identified the target
        self.signing = signing
        # UDP: read datagrams ourselves (recvmsg), so each message is attributed to the address it
        # came from (pymavlink's mavudp keeps no per-message sender: ``last_address`` is only set
        # in broadcast mode, ``clients`` collects every sender and ``write`` answers them all).
        self._udp_sock: socket.socket | None = getattr(conn, "port", None) if endpoint.kind in ("udpin", "udpout") else None
        self._kernel_stamps = False
        if self._udp_sock is not None and sys.platform.startswith("linux"):
            try:
                self._udp_sock.setsockopt(socket.SOL_SOCKET, _SO_TIMESTAMPNS, 1)
                self._kernel_stamps = True
            except OSError:
                pass
        self.peer: tuple[str, int] | None = None  # UDP address of the target, locked at identification
        self._pending: collections.deque[tuple[Any, Any, float]] = collections.deque()
        self._resume: asyncio.Handle | None = None
        self._last_addr: Any = None  # sender of the message being handled
        # State that waited longer than this in the socket is dropped unread (None: never).
        self.max_state_age_s: float | None = None
        self._n = {f.name: 0 for f in dataclasses.fields(LinkCounters)}

    @property
    def counters(self) -> LinkCounters:
        return LinkCounters(**self._n)

    @classmethod
    def open(cls, endpoint: Endpoint, source_system: int = 1, signing_key: bytes | None = None) -> Link:
        """Open the endpoint (binds / connects; no traffic yet). Raises :class:`LinkError`.

        ``signing_key`` (32 bytes): sign everything we send and accept only frames signed with it.
        """
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
        if signing_key is not None:
            if len(signing_key) != 32:
                conn.close()
                raise LinkError(f"signing key must be 32 bytes, got {len(signing_key)}")
            # allow_unsigned_callback None: an unsigned frame is refused like a wrongly signed one
            conn.setup_signing(signing_key, sign_outgoing=True, allow_unsigned_callback=None)
            # the signature before the timestamp: one wrongly signed frame must not stall the stream
            verify_signature_first(conn.mav)
        return cls(endpoint, conn, signing=signing_key is not None)

    # ------------------------------------------------------------------ receiving
    def start_reading(self, handler: Callable[[Any], None]) -> None:
        """Call ``handler(msg)`` from the event loop for every message from the target."""
        self._handler = handler
        if not self._reading:
            loop = asyncio.get_running_loop()
            loop.add_reader(self._conn.fd, self._drain)
            self._reading = True
            if self._pending and self._resume is None:  # decoded before a previous stop_reading
                self._resume = loop.call_soon(self._drain)

    def stop_reading(self) -> None:
        if self._resume is not None:
            self._resume.cancel()
            self._resume = None
        if self._reading:
            try:
                asyncio.get_running_loop().remove_reader(self._conn.fd)
            except RuntimeError:  # loop already closed
                pass
            self._reading = False

    def _next(self) -> tuple[Any, Any, float] | None:
        """The next (message, sender address or None, seconds it waited in the socket); None when
        nothing is waiting; ``_SKIPPED`` for a datagram read that gave nothing to handle."""
        if self._pending:
            return self._pending.popleft()
        if self._udp_sock is None:
            msg = self._conn.recv_msg()  # TCP / serial: one peer by construction
            return None if msg is None else (msg, None, 0.0)
        try:
            data, ancdata, _flags, addr = self._udp_sock.recvmsg(65535, socket.CMSG_SPACE(16) if self._kernel_stamps else 0)
        except (BlockingIOError, InterruptedError):
            return None
        except ConnectionRefusedError:  # ICMP port unreachable from an earlier send: nobody there yet
            return _SKIPPED
        if self.peer is not None and addr != self.peer:
            # not even decoded: a flood from elsewhere costs one recvmsg each, and counts against
            # the wake-up's budget like any datagram (else it could keep the reader busy forever)
            self._n["foreign_peer"] += 1
            return _SKIPPED
        age = 0.0
        for level, kind, raw in ancdata:
            if level == socket.SOL_SOCKET and kind == _SO_TIMESTAMPNS and len(raw) >= _TIMESPEC.size:
                sec, nsec = _TIMESPEC.unpack_from(raw)
                age = max(0.0, time.time() - (sec + nsec * 1e-9))  # time it waited in the socket
        for m in self._conn.mav.parse_buffer(data) or []:
            self._pending.append((m, addr, age))
        return self._pending.popleft() if self._pending else _SKIPPED

    def _drain(self) -> None:
        """Decode up to MAX_MESSAGES_PER_WAKEUP waiting messages; never blocks."""
        if self._resume is not None:  # draining now: a scheduled resume would be a second slice
            self._resume.cancel()
            self._resume = None
        for _ in range(MAX_MESSAGES_PER_WAKEUP):
            try:
                item = self._next()
            except (ConnectionError, OSError) as exc:
                self._handler_error(exc)
                return
            if item is None:
                return
            if item is _SKIPPED:
                continue
            self._dispatch(*item)
            if not self._reading:  # the handler stopped reading (e.g. wait_heartbeat finished)
                return
        # Budget spent with (maybe) more waiting: yield to the other tasks. A socket with data wakes
        # the reader again by itself (level-triggered); messages already decoded (several per
        # datagram) or buffered by pymavlink (TCP / serial) need an explicit resume.
        self._n["reader_yields"] += 1
        if self._pending or self._udp_sock is None:
            self._resume = asyncio.get_running_loop().call_soon(self._drain)

    def _dispatch(self, msg: Any, addr: Any, age_s: float) -> None:
        kind = msg.get_type()
        if kind == "BAD_DATA":
            reason = str(getattr(msg, "reason", ""))
            self._n["bad_signature" if "signature" in reason.lower() else "bad_data"] += 1
            return
        target = self.target
        if target is not None:
            if msg.get_srcSystem() != target.system or msg.get_srcComponent() != target.component:
                if kind in SETPOINT_MESSAGES and int(getattr(msg, "target_system", 0) or 0) in (0, target.system):
                    # another controller's setpoint for our autopilot, relayed to us (a router, an
                    # autopilot forwarding between links): evidence, never state; the handler judges it
                    self._n["foreign_setpoint"] += 1
                    if self.on_received is not None:
                        self.on_received(msg)
                    if self._handler is not None:
                        self._handler(msg)
                    return
                self._n["not_target"] += 1  # other systems / components are not ours to follow
                return
            if kind == "HEARTBEAT" and not (
                is_vehicle_heartbeat(msg) and msg.autopilot == target.autopilot and msg.type == target.vehicle_type
            ):
                self._n["not_autopilot_heartbeat"] += 1  # a GCS-type HEARTBEAT with our autopilot's ids: a spoof
                return
            if kind in STATE_MESSAGES and self.max_state_age_s is not None and age_s > self.max_state_age_s:
                self._n["stale_state"] += 1
                return
        if self.on_received is not None:
            self.on_received(msg)
        if kind == "COMMAND_ACK" and not self.ack_is_ours(msg):
            self._n["foreign_ack"] += 1  # logged, never handed on: another GCS's command was answered
            return
        self._last_addr = addr
        if self._handler is not None:
            self._handler(msg)

    def ack_is_ours(self, msg: Any) -> bool:
        """A COMMAND_ACK answers *our* command: its target system / component are ours (0: not
        filled in, as MAVLink 1 and old autopilots send it). PX4 and ArduPilot address each ACK to
        the command's sender and send it on every link: one meant for another GCS must not count."""
        system = int(getattr(msg, "target_system", 0) or 0)
        component = int(getattr(msg, "target_component", 0) or 0)
        return system in (0, int(self._conn.mav.srcSystem)) and component in (0, MAV_COMP_ID_ONBOARD_COMPUTER)

    def _from_configured_address(self, addr: Any) -> bool:
        """``udpout`` names the autopilot's address: only it may identify as the autopilot. (``udpin``
        cannot know it in advance: the first autopilot HEARTBEAT fixes it; sign the link to
        authenticate it.)"""
        if self.endpoint.kind != "udpout" or addr is None:
            return True
        dest = getattr(self._conn, "destination_addr", None)
        if dest is None:
            return True
        try:
            host = socket.gethostbyname(dest[0])
        except OSError:
            return True
        return (addr[0], addr[1]) == (host, int(dest[1]))

    def _lock_udpin(self) -> None:
        """``udpin``: from now on send only to the locked peer (pymavlink answers every sender)."""
        if self.peer is not None and self.endpoint.kind == "udpin":
            self._conn.clients = {self.peer}
            self._conn.clients_last_alive = {self.peer: time.time()}

    def _handler_error(self, exc: BaseException) -> None:
        self.stop_reading()
        self.error = LinkError(f"{self.endpoint}: link failed: {exc}")

    async def wait_heartbeat(
        self, timeout_s: float, target_system: int | None = None, announce: Callable[[str], None] | None = None,
        progress_every_s: float = 5.0,
    ) -> VehicleId:  # fmt: skip
        """Wait for an autopilot HEARTBEAT (from ``target_system`` if given); :class:`LinkError` on timeout.

        We announce ourselves with our own HEARTBEAT every second meanwhile, because a UDP
        autopilot (``udpout``) only learns our address from what we send. ``announce(line)``: told
        that we wait (with the time waited every ``progress_every_s``) and what answered.
        """
        loop = asyncio.get_running_loop()
        found: asyncio.Future[VehicleId] = loop.create_future()
        found_addr: Any = None

        def handler(msg: Any) -> None:
            nonlocal found_addr
            if found.done() or not is_vehicle_heartbeat(msg):
                return
            if target_system is not None and msg.get_srcSystem() != target_system:
                return
            if not self._from_configured_address(self._last_addr):
                self._n["foreign_peer"] += 1  # udpout: the autopilot is the address we were told
                return
            self.first_heartbeat = msg
            found_addr = self._last_addr
            found.set_result(VehicleId(msg.get_srcSystem(), msg.get_srcComponent(), msg.autopilot, msg.type))

        self.start_reading(handler)
        start = loop.time()
        deadline = start + timeout_s
        next_progress = start + progress_every_s
        if announce is not None:
            announce(f"waiting for a HEARTBEAT on {self.endpoint} (up to {timeout_s:g} s)")
        try:
            while not found.done():
                now = loop.time()
                if announce is not None and now >= next_progress:
                    next_progress = now + progress_every_s
                    announce(f"waiting for a HEARTBEAT on {self.endpoint}: {now - start:.0f} s of up to {timeout_s:g} s")
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
            refused = self._n["bad_signature"]
            hint = f" ({refused} frames refused: unsigned or signed with another key)" if refused else ""
            raise LinkError(f"no HEARTBEAT from an autopilot on {self.endpoint} within {timeout_s:g} s{hint}")
        self.target = found.result()
        if announce is not None:
            t = self.target
            announce(f"HEARTBEAT from system {t.system} component {t.component} (autopilot {t.autopilot}) "
                     f"after {loop.time() - start:.1f} s")  # fmt: skip
        # UDP: lock to the address the autopilot spoke from (the first peer): the same ids from any
        # other address are a second sender, refused from now on.
        self.peer = found_addr
        self._lock_udpin()
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
