"""``MockAutopilot``: the pure :class:`~sitl_mock.autopilot.Autopilot` wired to loopback sockets.

UDP (PX4 SITL offboard-API link style): one link bound to ``udp_local_port`` that sends to
``udp_remote`` and to every address that has sent to it. TCP (ArduPilot SITL style): a server,
one link per client. Each peer has its own pymavlink ``MAVLink`` object (sequence numbers,
parser), srcSystem 1, srcComponent 1, MAVLink 2.

Clock: real time × ``speed`` (a task steps the simulation at ``step_dt_s`` of simulated time),
or lockstep (each received setpoint advances ``lockstep_dt_s``; while idle, HEARTBEAT and
SYS_STATUS go out once per wall second so clients can connect).
"""

from __future__ import annotations

import asyncio
import csv
import heapq
import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, TextIO

from pymavlink.dialects.v20 import common as mavlink

from sitl_mock.autopilot import SETPOINT_IDS, Autopilot, Out
from sitl_mock.config import MockConfig
from sitl_mock.dynamics import VehicleState
from sitl_mock.faults import FaultInjector
from sitl_mock.signing import verify_signature_first

UDP_LINK = 0
_KEEPALIVE_IDS = (mavlink.MAVLINK_MSG_ID_HEARTBEAT, mavlink.MAVLINK_MSG_ID_SYS_STATUS)
_ATTITUDE_ID = mavlink.MAVLINK_MSG_ID_ATTITUDE_QUATERNION
_RELAYED_IDS = SETPOINT_IDS | {mavlink.MAVLINK_MSG_ID_SET_POSITION_TARGET_GLOBAL_INT}


@dataclass(frozen=True)
class Ports:
    """Bound ports (None: transport disabled)."""

    udp: int | None
    tcp: int | None


# MAVLink 2 signing timestamps count 10 µs units from 2015-01-01 (the MAVLink signing spec).
_SIGNING_EPOCH_UNIX_S = 1420070400


def new_mavlink(signing_key: bytes | None = None, signing: Any = None) -> mavlink.MAVLink:
    """A per-peer encoder/parser; with ``signing_key`` it signs what it packs and refuses unsigned or
    wrongly signed frames (pymavlink raises "Invalid signature"; no unsigned callback: refused), the
    signature checked before the frame's timestamp is believed (see sitl_mock.signing).
    ``signing``: the signing state (timestamps of the streams seen) to share: one per link, as PX4
    and ArduPilot keep it, so a signed frame replayed from another UDP port is an old one."""
    mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    mav.robust_parsing = True
    if signing_key is not None:
        verify_signature_first(mav)
    if signing is not None:
        mav.signing = signing
    elif signing_key is not None:
        mav.signing.secret_key = signing_key
        mav.signing.sign_outgoing = True
        mav.signing.link_id = 0
        mav.signing.allow_unsigned_callback = None
        mav.signing.timestamp = int(max(time.time() - _SIGNING_EPOCH_UNIX_S, 0.0) * 100_000)
    return mav


def parse_datagram(mav: mavlink.MAVLink, data: bytes, on_bad: Callable[[str], None] | None = None) -> list[mavlink.MAVLink_message]:
    """Decode the whole MAVLink frames of one UDP datagram with pymavlink's ``decode`` (CRC and,
    with signing, signature checked; failures are dropped and reported to ``on_bad(reason)``),
    skipping the byte-by-byte parser. Anything unexpected (a partial frame, garbage) goes to
    pymavlink's resynchronising ``parse_buffer``."""
    out: list[mavlink.MAVLink_message] = []
    i, n = 0, len(data)
    while i < n:
        marker = data[i]
        if marker == mavlink.PROTOCOL_MARKER_V2 and i + 3 <= n:
            length = 12 + data[i + 1] + (mavlink.MAVLINK_SIGNATURE_BLOCK_LEN if data[i + 2] & 1 else 0)
        elif marker == mavlink.PROTOCOL_MARKER_V1 and i + 2 <= n:
            length = 8 + data[i + 1]
        else:
            length = 0
        if length == 0 or i + length > n:
            return out + [m for m in (mav.parse_buffer(data[i:]) or []) if m.get_type() != "BAD_DATA"]
        try:
            out.append(mav.decode(bytearray(data[i : i + length])))
        except mavlink.MAVError as exc:  # CRC, length or signature: dropped, as the real autopilots do
            if on_bad is not None:
                on_bad(str(exc))
        i += length
    return out


def encode(mav: mavlink.MAVLink, msg: mavlink.MAVLink_message) -> bytes:
    """Pack ``msg`` with ``mav``'s sequence number (MAVLink 2) and advance it."""
    data = msg.pack(mav)
    mav.seq = (mav.seq + 1) & 0xFF
    return bytes(data)


_TCP_BACKLOG_BYTES = 1 << 20
_MTU = 1400  # like PX4, pack several messages into one UDP datagram up to about this size


class _Peer:
    """One remote endpoint: its encoder/parser, an output buffer and how to write to it.

    Messages produced in one step (or in reply to one datagram) are packed into as few
    datagrams as possible, as PX4's MAVLink module does; :meth:`flush` sends them.
    """

    __slots__ = ("mav", "write", "link", "buffer")

    def __init__(self, link: int, write: Callable[[bytes], None], signing_key: bytes | None = None, signing: Any = None) -> None:
        self.mav = new_mavlink(signing_key, signing)
        self.write = write
        self.link = link
        self.buffer = bytearray()

    def queue(self, data: bytes) -> None:
        if len(self.buffer) + len(data) > _MTU and self.buffer:
            self.flush()
        self.buffer += data

    def flush(self) -> None:
        if self.buffer:
            self.write(bytes(self.buffer))
            self.buffer.clear()


class _UdpProtocol(asyncio.DatagramProtocol):
    def __init__(self, owner: MockAutopilot) -> None:
        self.owner = owner

    def datagram_received(self, data: bytes, addr: Any) -> None:
        self.owner._udp_datagram(data, addr)

    def error_received(self, exc: Exception) -> None:  # ICMP port unreachable: nobody listening yet
        pass


class MockAutopilot:
    """The mock autopilot on loopback sockets. Use ``async with MockAutopilot(config) as mock``.

    ``mock.ports`` gives the bound ports, ``mock.truth`` the true vehicle state,
    ``mock.autopilot`` the state machine (mode, armed, params, log).
    """

    def __init__(self, config: MockConfig) -> None:
        config.validate()
        self.config = config
        self.autopilot = Autopilot(config)
        self.faults = FaultInjector(config.faults, self.autopilot.rng_faults)
        self.autopilot.fault_injector = self.faults  # fault windows relative to OFFBOARD entry (tests/faults)
        self.ports = Ports(None, None)
        self._udp: asyncio.DatagramTransport | None = None
        self._udp_peers: dict[Any, _Peer] = {}
        self._tcp_server: asyncio.base_events.Server | None = None
        self._tcp_peers: dict[int, _Peer] = {}
        self._next_link = 1
        self._tasks: list[asyncio.Task[None]] = []
        self._delayed: list[tuple[float, int, _Peer, bytes]] = []
        self._delay_seq = 0
        self._last_heartbeat_wall = -math.inf
        self._truth_file: TextIO | None = None
        self._truth_writer: Any = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._done: asyncio.Event | None = None
        self.received = 0
        self.relayed = 0  # setpoints relayed from one client to the others (config.relay_setpoints)
        self.steps = 0
        self._signing_key = config.signing_key()
        # one signing state for the UDP link (every UDP address shares it, like a real autopilot's
        # link): a stream's timestamp seen from one address is not new again from another
        self._udp_signing = new_mavlink(self._signing_key).signing if self._signing_key is not None else None
        self.rejected_signature = 0  # frames refused: unsigned or wrongly signed (signing on)
        self.rejected_corrupt = 0  # frames refused: CRC / length
        # called with every accepted message and the sender (UDP address or TCP link number)
        self.on_received: Callable[[mavlink.MAVLink_message, Any], None] | None = None
        self._speed = config.speed  # × real time on its own clock (set_speed changes it while running)

    # ------------------------------------------------------------------------------------------
    # Lifecycle
    # ------------------------------------------------------------------------------------------
    async def __aenter__(self) -> MockAutopilot:
        await self.start()
        return self

    async def __aexit__(self, *exc: object) -> None:
        await self.stop()

    async def start(self) -> None:
        cfg = self.config
        loop = asyncio.get_running_loop()
        self._loop = loop
        self._done = asyncio.Event()
        udp_port = tcp_port = None
        if cfg.udp_local_port is not None:
            transport, _ = await loop.create_datagram_endpoint(
                lambda: _UdpProtocol(self), local_addr=(cfg.host, cfg.udp_local_port)
            )
            self._udp = transport
            udp_port = transport.get_extra_info("sockname")[1]
            self.autopilot.add_link(UDP_LINK)
            if cfg.udp_remote is not None:
                self._udp_peer(cfg.udp_remote)
        if cfg.tcp_port is not None:
            self._tcp_server = await asyncio.start_server(self._tcp_client, cfg.host, cfg.tcp_port)
            tcp_port = self._tcp_server.sockets[0].getsockname()[1]
        self.ports = Ports(udp_port, tcp_port)
        if cfg.truth_log:
            self._truth_file = open(cfg.truth_log, "w", newline="")
            self._truth_writer = csv.writer(self._truth_file)
            self._truth_writer.writerow(TRUTH_COLUMNS)
        self._emit(self.autopilot.due_telemetry())
        self._flush()
        if cfg.lockstep:
            self._tasks.append(asyncio.create_task(self._keepalive()))
        else:
            self._tasks.append(asyncio.create_task(self._clock()))

    async def stop(self) -> None:
        for task in self._tasks:
            task.cancel()
        for task in self._tasks:
            try:
                await task
            except asyncio.CancelledError:
                pass
        self._tasks.clear()
        if self._udp is not None:
            self._udp.close()
            self._udp = None
        if self._tcp_server is not None:
            self._tcp_server.close()
            for peer in list(self._tcp_peers.values()):
                peer.write(b"")
            await self._tcp_server.wait_closed()
            self._tcp_server = None
        if self._truth_file is not None:
            self._truth_file.close()
            self._truth_file = None
        if self._done is not None:
            self._done.set()

    def request_stop(self) -> None:
        """Make :meth:`wait_done` return (e.g. from a signal handler)."""
        if self._done is not None:
            self._done.set()

    async def wait_done(self) -> None:
        """Until ``duration_s`` of simulated time has run (or :meth:`stop`)."""
        assert self._done is not None, "start() first"
        await self._done.wait()

    # ------------------------------------------------------------------------------------------
    # State and injections
    # ------------------------------------------------------------------------------------------
    @property
    def truth(self) -> VehicleState:
        return self.autopilot.truth

    @property
    def time_s(self) -> float:
        return self.autopilot.time_s

    def inject_takeover(self, mode: str | None = None) -> None:
        self._emit(self.autopilot.inject_takeover(mode))
        self._flush()

    def inject_estimator_reset(self, delta_ned_m: tuple[float, float, float]) -> None:
        self._emit(self.autopilot.inject_estimator_reset(delta_ned_m))
        self._flush()

    def inject_gust(self, velocity_ned_m_s: tuple[float, float, float], duration_s: float = 1.0) -> None:
        self.autopilot.inject_gust(velocity_ned_m_s, duration_s)

    def set_speed(self, speed: float) -> None:
        """Run the own clock at ``speed`` × real time from now on (not in lockstep): e.g. a test
        that has nothing on the link any more lets the vehicle's remaining seconds pass faster.
        The physics steps are the same whatever the speed; only the wall-clock pacing changes."""
        if self.config.lockstep:
            raise ValueError("speed: a lockstep mock advances on setpoints, it has no pace to change")
        if not (math.isfinite(speed) and speed > 0.0):
            raise ValueError(f"speed: must be finite and > 0, got {speed}")
        self._speed = speed

    async def wait_for(self, predicate: Callable[[MockAutopilot], bool], timeout_s: float = 10.0) -> bool:
        """Poll ``predicate(self)`` on the event loop until true or ``timeout_s`` wall seconds."""
        loop = asyncio.get_running_loop()
        deadline = loop.time() + timeout_s
        while not predicate(self):
            if loop.time() > deadline:
                return False
            await asyncio.sleep(0.002)
        return True

    # ------------------------------------------------------------------------------------------
    # Clock
    # ------------------------------------------------------------------------------------------
    async def _clock(self) -> None:
        loop = asyncio.get_running_loop()
        cfg = self.config
        dt = cfg.step_dt_s
        wall0 = loop.time()
        sim0 = self.autopilot.time_s
        speed = self._speed
        while True:
            now_wall = loop.time()
            if self._speed != speed:  # set_speed: re-anchor, so the new pace counts from now
                wall0, sim0, speed = now_wall, self.autopilot.time_s, self._speed
            target = sim0 + (now_wall - wall0) * speed
            if target - self.autopilot.time_s > 0.25 * speed:
                # More than 0.25 s (wall) behind: the host cannot keep up. Run slower than asked
                # rather than in bursts that would starve the clients.
                wall0, sim0 = now_wall, self.autopilot.time_s
                target = sim0 + dt
            batch = 0
            while self.autopilot.time_s + dt <= target + 1e-9:
                self._step(dt, flush=False)
                batch += 1
                if self._finished():
                    self._flush()
                    return
                if batch >= 50:  # let received messages in when the host cannot keep up
                    break
            self._flush()  # one burst of datagrams per wake-up, packed up to the MTU
            now_wall = loop.time()
            next_wall = wall0 + (self.autopilot.time_s + dt - sim0) / speed
            await asyncio.sleep(max(0.0, next_wall - now_wall))

    async def _keepalive(self) -> None:
        """Lockstep: HEARTBEAT + SYS_STATUS once per wall second so clients can connect."""
        loop = asyncio.get_running_loop()
        while True:
            if loop.time() - self._last_heartbeat_wall >= 1.0:
                self._send_keepalive()
            await asyncio.sleep(0.25)

    def _send_keepalive(self) -> None:
        assert self._loop is not None
        self._last_heartbeat_wall = self._loop.time()
        if self.faults.in_blackout(self.autopilot.time_s):
            return
        for msgid in _KEEPALIVE_IDS:
            msg = self.autopilot.build(msgid)
            for peer in self._peers_of(None):
                peer.queue(encode(peer.mav, msg))  # not through the fault RNG: keeps runs deterministic
        self._flush()

    def _finished(self) -> bool:
        duration = self.config.duration_s
        if duration is not None and self.autopilot.time_s >= duration - 1e-9:
            assert self._done is not None
            self._done.set()
            return True
        return False

    def _step(self, dt: float, flush: bool = True) -> None:
        ap = self.autopilot
        events = ap.step(dt)
        self.steps += 1
        if events:
            self._emit(events)
        self._emit(ap.due_telemetry())
        if self._delayed:
            self._flush_delayed()
        if self._truth_writer is not None:
            self._truth_writer.writerow(truth_row(ap))
        if flush:
            self._flush()

    def _flush(self) -> None:
        for peer in self._udp_peers.values():
            peer.flush()
        for peer in self._tcp_peers.values():
            peer.flush()

    # ------------------------------------------------------------------------------------------
    # Sending
    # ------------------------------------------------------------------------------------------
    def _peers_of(self, link: int | None) -> list[_Peer]:
        if link is None:
            return list(self._udp_peers.values()) + list(self._tcp_peers.values())
        if link == UDP_LINK:
            return list(self._udp_peers.values())
        peer = self._tcp_peers.get(link)
        return [peer] if peer is not None else []

    def _emit(self, outs: list[Out]) -> None:
        now = self.autopilot.time_s
        faults = self.faults
        reorder_on = faults.config.attitude_reorder > 0.0
        for link, msg in outs:
            if link is None or msg.get_msgId() == mavlink.MAVLINK_MSG_ID_HEARTBEAT:
                if self._loop is not None:
                    self._last_heartbeat_wall = self._loop.time()
            reorder = reorder_on and msg.get_msgId() == _ATTITUDE_ID and not getattr(msg, "fault_injected", False)
            for peer in self._peers_of(link):
                data = encode(peer.mav, msg)
                for frame in faults.reorder_attitude(peer, data) if reorder else (data,):
                    for release, chunk in faults.outgoing(frame, now):
                        if release <= now:
                            peer.queue(chunk)
                        else:
                            self._delay_seq += 1
                            heapq.heappush(self._delayed, (release, self._delay_seq, peer, chunk))

    def _relay(self, source: _Peer, msg: mavlink.MAVLink_message) -> None:
        """Forward ``msg`` unchanged (its sender's ids) to every other client, as a router does."""
        others = [peer for peer in self._peers_of(None) if peer is not source]
        for peer in others:
            peer.queue(msg.get_msgbuf())
        if others:
            self.relayed += 1

    def _flush_delayed(self) -> None:
        now = self.autopilot.time_s
        while self._delayed and self._delayed[0][0] <= now:
            _, _, peer, chunk = heapq.heappop(self._delayed)
            peer.queue(chunk)

    # ------------------------------------------------------------------------------------------
    # Receiving
    # ------------------------------------------------------------------------------------------
    def _udp_peer(self, addr: Any, peer: _Peer | None = None) -> _Peer:
        """The peer of ``addr``, created (or ``peer`` adopted) on first use."""
        known = self._udp_peers.get(addr)
        if known is not None:
            return known
        udp = self._udp
        assert udp is not None

        def write(data: bytes, addr: Any = addr) -> None:
            if data and self._udp is not None:
                udp.sendto(data, addr)

        if peer is None:
            peer = _Peer(UDP_LINK, write, self._signing_key, self._udp_signing)
        else:
            peer.write = write
        self._udp_peers[addr] = peer
        return peer

    def _udp_datagram(self, data: bytes, addr: Any) -> None:
        if self._signing_key is not None and addr not in self._udp_peers:
            # With signing, an address becomes a peer (is sent telemetry) only once it sent a validly
            # signed frame: an unsigned or wrongly keyed sender learns nothing from us.
            if self.config.faults.loss > 0.0 and self.faults.drop_incoming():
                return
            probe = _Peer(UDP_LINK, lambda _data: None, self._signing_key, self._udp_signing)
            msgs = self._parse(probe, data, datagram=True)
            if msgs:
                self._handle(self._udp_peer(addr, probe), msgs, addr)
            return
        self._receive(self._udp_peer(addr), data, datagram=True, addr=addr)

    def _count_bad(self, reason: str) -> None:
        if "signature" in reason.lower():
            self.rejected_signature += 1
        else:
            self.rejected_corrupt += 1

    async def _tcp_client(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        link = self._next_link
        self._next_link += 1

        def write(data: bytes) -> None:
            if not data:
                writer.close()
            elif not writer.is_closing() and writer.transport.get_write_buffer_size() < _TCP_BACKLOG_BYTES:
                writer.write(data)  # a client that stops reading loses telemetry, like a full serial buffer

        peer = _Peer(link, write, self._signing_key)
        self._tcp_peers[link] = peer
        self.autopilot.add_link(link)
        try:
            while True:
                data = await reader.read(65536)
                if not data:
                    break
                self._receive(peer, data, addr=link)
        except (ConnectionError, asyncio.CancelledError):
            pass
        finally:
            self._tcp_peers.pop(link, None)
            self.autopilot.remove_link(link)
            writer.close()

    def _receive(self, peer: _Peer, data: bytes, datagram: bool = False, addr: Any = None) -> None:
        if self.config.faults.loss > 0.0 and self.faults.drop_incoming():
            return
        msgs = self._parse(peer, data, datagram)
        if msgs:
            self._handle(peer, msgs, addr)

    def _parse(self, peer: _Peer, data: bytes, datagram: bool) -> list[mavlink.MAVLink_message]:
        try:
            if datagram:
                return parse_datagram(peer.mav, data, self._count_bad)
            msgs = peer.mav.parse_buffer(data) or []
        except Exception:  # malformed traffic must never stop the mock  # noqa: BLE001
            return []
        good = []
        for msg in msgs:
            if msg.get_type() == "BAD_DATA":
                self._count_bad(str(getattr(msg, "reason", "")))
            else:
                good.append(msg)
        return good

    def _handle(self, peer: _Peer, msgs: list[mavlink.MAVLink_message], addr: Any) -> None:
        ap = self.autopilot
        lockstep = self.config.lockstep
        for msg in msgs:
            if msg.get_type() == "BAD_DATA":
                continue
            self.received += 1
            if self.on_received is not None:
                self.on_received(msg, addr)
            replies = ap.handle(msg, peer.link)
            if replies:
                self._emit(replies)
            if self.config.relay_setpoints and msg.get_msgId() in _RELAYED_IDS:
                self._relay(peer, msg)
            if lockstep and msg.get_msgId() in SETPOINT_IDS and not self._finished():
                self._step(self.config.lockstep_dt_s)
                if self._finished():
                    break
        self._flush()


TRUTH_COLUMNS = (
    "time_s", "x_m", "y_m", "z_m", "vx_m_s", "vy_m_s", "vz_m_s", "qw", "qx", "qy", "qz",
    "p_rad_s", "q_rad_s", "r_rad_s", "armed", "mode", "landed", "est_x_m", "est_y_m", "est_z_m",
)


def truth_row(ap: Autopilot) -> list[object]:
    s = ap.truth
    est = ap.est_position_ned_m
    return [
        f"{s.time_s:.4f}", *(f"{v:.5f}" for v in s.position_ned_m), *(f"{v:.5f}" for v in s.velocity_ned_m_s),
        *(f"{v:.6f}" for v in s.q_ned_frd), *(f"{v:.5f}" for v in s.rates_frd_rad_s),
        int(ap.armed), ap.mode.name, int(s.landed), *(f"{v:.5f}" for v in est),
    ]
