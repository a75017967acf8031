"""MAVLink 2 link to one PX4 (ROS-free): UDP or serial transport, robust framing, optional signing, counters.

Connection URLs:
- ``udp://127.0.0.1:14540`` — bind (listen) on that address, PX4 SITL style: PX4 sends to the port, replies go
  to the address of the last accepted frame from the target system (only validated frames move the peer).
- ``udpout://127.0.0.1:14580`` — send to that address from an ephemeral local port (replies come back to it).
- ``serial:///dev/ttyACM0`` or ``/dev/ttyACM0`` — a serial device opened raw at ``baud`` (termios).

Parsing never raises: every datagram (or serial chunk) is split into frames by the MAVLink 2 / 1 header, each
frame is decoded alone, and bad prefixes, truncations, CRC errors, unknown ids and refused signatures are
counted in :class:`LinkCounters`. With signing on (a 32-byte secret key), unsigned or wrongly signed frames
are refused and counted; outgoing frames are signed. Signing timestamp (MAVLink 2 signing spec: 10 µs units since
2015-01-01 00:00 UTC, following the wall clock, strictly increasing per (link id, system, component)): set before
EVERY outgoing frame to max(wall-clock timestamp, last + 1). pymavlink alone sets it once and then only adds 1 per
frame (``MAVLink_message.sign_packet``), so a link sending ~100 frames/s would fall behind the wall clock by nearly
the whole elapsed time (25 s after 25 s), and a receiver judging new streams against its own clock (pymavlink
accepts a new stream at most 60 s behind) would eventually refuse it.
"""

from __future__ import annotations

import hashlib
import hmac
import os
import select
import socket
import time
from collections.abc import Callable
from dataclasses import dataclass
from urllib.parse import urlparse

from fpr_px4_bridge.px4_protocol import MAV_COMP_ID_ONBOARD_COMPUTER, import_mavlink

mavlink = import_mavlink()

__all__ = [
    "ConnectionSpec",
    "LinkCounters",
    "MavlinkLink",
    "advance_signing_timestamp",
    "enable_signing",
    "load_signing_key",
    "parse_connection_url",
    "signing_timestamp",
    "split_frames",
]

_MARKER_V2 = 0xFD
_MARKER_V1 = 0xFE
_HEADER_V2 = 10
_HEADER_V1 = 6
_SIGNATURE_LEN = 13
_IFLAG_SIGNED = 0x01
_MAX_DATAGRAM = 65535
#: MAVLink signing timestamps count 10 µs since 2015-01-01 00:00 UTC.
_SIGNING_EPOCH = 1420070400.0


@dataclass(frozen=True)
class ConnectionSpec:
    """A parsed connection URL."""

    kind: str  #: "udp_listen", "udp_send" or "serial"
    host: str = ""
    port: int = 0
    device: str = ""


def parse_connection_url(url: str) -> ConnectionSpec:
    """Parse ``udp://host:port``, ``udpin://``, ``udpout://host:port``, ``serial:///dev/x`` or ``/dev/x``."""
    url = url.strip()
    if url.startswith("/"):
        return ConnectionSpec(kind="serial", device=url)
    parsed = urlparse(url)
    if parsed.scheme == "serial":
        device = parsed.path or parsed.netloc
        if not device:
            raise ValueError(f"serial URL without a device: {url!r}")
        return ConnectionSpec(kind="serial", device=device)
    if parsed.scheme in ("udp", "udpin", "udpout"):
        try:
            port = parsed.port
        except ValueError as error:
            raise ValueError(f"bad port in {url!r}: {error}") from None
        host = parsed.hostname or "127.0.0.1"
        if port is None:
            raise ValueError(f"UDP URL needs a port: {url!r}")
        kind = "udp_send" if parsed.scheme == "udpout" else "udp_listen"
        if kind == "udp_send" and port == 0:
            raise ValueError(f"udpout needs a destination port: {url!r}")
        return ConnectionSpec(kind=kind, host=host, port=port)
    raise ValueError(f"unsupported connection URL {url!r} (udp://, udpout://, serial://, /dev/...)")


def load_signing_key(path: str) -> bytes:
    """Read a MAVLink 2 signing secret: a file with 64 hex digits or exactly 32 raw bytes."""
    with open(path, "rb") as handle:
        content = handle.read()
    text = content.strip()
    if len(text) == 64:
        try:
            return bytes.fromhex(text.decode("ascii"))
        except (UnicodeDecodeError, ValueError):
            pass
    if len(content) == 32:
        return content
    raise ValueError(f"signing key file {path!r} must hold 64 hex digits or 32 raw bytes")


def signing_timestamp(unix_time: float | None = None) -> int:
    """MAVLink signing timestamp (10 µs units since 2015-01-01) of ``unix_time`` (default: now)."""
    now = time.time() if unix_time is None else unix_time
    return max(0, int((now - _SIGNING_EPOCH) * 100_000))


def enable_signing(mav, key: bytes, link_id: int, unix_time: float) -> None:
    """Sign every outgoing frame of the pymavlink codec ``mav`` with ``key`` (32 bytes) and refuse every unsigned
    incoming one (fpr_px4_bridge's link and fpr_sim's PX4 emulator: one implementation)."""
    if len(key) != 32:
        raise ValueError("MAVLink 2 signing key must be 32 bytes")
    mav.signing.secret_key = bytes(key)
    mav.signing.link_id = int(link_id) & 0xFF
    mav.signing.timestamp = signing_timestamp(unix_time)
    mav.signing.sign_outgoing = True
    mav.signing.allow_unsigned_callback = None  # refuse every unsigned frame


def advance_signing_timestamp(mav, unix_time: float) -> None:
    """Before each signed frame: max(wall-clock timestamp, last + 1) (module doc). pymavlink signs with
    ``signing.timestamp`` and then adds 1 (so it already holds last + 1), and raises it to any newer timestamp it
    accepts from a peer."""
    signing = mav.signing
    signing.timestamp = max(signing_timestamp(unix_time), int(signing.timestamp))


@dataclass
class LinkCounters:
    """What the link received and sent; ``garbage`` is what :attr:`rx_rejected` sums for the status."""

    rx_datagrams: int = 0
    rx_bytes: int = 0
    rx_frames: int = 0          #: frames decoded and accepted
    rx_bad_bytes: int = 0       #: runs of bytes that did not start a frame (bad prefix)
    rx_truncated: int = 0       #: frames cut short by the end of a datagram
    rx_bad_frames: int = 0      #: CRC / length / payload errors, bad incompat flags
    rx_unknown: int = 0         #: valid frames with a message id not in the dialect
    rx_unsigned: int = 0        #: unsigned frames refused because signing is on
    rx_bad_signature: int = 0   #: signed frames whose signature or timestamp failed
    rx_mavlink1: int = 0        #: MAVLink 1 frames accepted (signing off) or refused (signing on)
    rx_other_system: int = 0    #: accepted frames from other systems than the target (ignored by the bridge)
    tx_frames: int = 0
    tx_bytes: int = 0
    tx_errors: int = 0

    @property
    def rx_rejected(self) -> int:
        """Malformed, unknown or refused (unsigned / bad signature) input, for ``UavStatus.rx_garbage``."""
        return (self.rx_bad_bytes + self.rx_truncated + self.rx_bad_frames + self.rx_unknown
                + self.rx_unsigned + self.rx_bad_signature)


@dataclass
class _Chunk:
    """A piece of a byte stream: a candidate frame, or garbage with a reason."""

    data: bytes
    frame: bool
    reason: str = ""
    marker: int = 0
    signed: bool = False


def split_frames(data: bytes, final: bool = True) -> tuple[list[_Chunk], bytes]:
    """Cut ``data`` into candidate MAVLink frames and garbage runs. Never raises.

    Returns ``(chunks, rest)``: ``rest`` is an incomplete frame at the end, kept for the next call of a
    stream (``final=False``, serial); with ``final=True`` (a UDP datagram) it is reported as truncated.
    """
    chunks: list[_Chunk] = []
    i = 0
    n = len(data)
    while i < n:
        marker = data[i]
        if marker not in (_MARKER_V2, _MARKER_V1):
            j = i + 1
            while j < n and data[j] not in (_MARKER_V2, _MARKER_V1):
                j += 1
            chunks.append(_Chunk(data[i:j], frame=False, reason="bad prefix"))
            i = j
            continue
        if marker == _MARKER_V2:
            if n - i < 3:
                break
            incompat = data[i + 2]
            if incompat & ~_IFLAG_SIGNED:
                chunks.append(_Chunk(data[i:i + 1], frame=False, reason="bad incompat flags"))
                i += 1
                continue
            signed = bool(incompat & _IFLAG_SIGNED)
            length = _HEADER_V2 + data[i + 1] + 2 + (_SIGNATURE_LEN if signed else 0)
        else:
            if n - i < 2:
                break
            signed = False
            length = _HEADER_V1 + data[i + 1] + 2
        if n - i < length:
            break
        chunks.append(_Chunk(data[i:i + length], frame=True, marker=marker, signed=signed))
        i += length
    rest = data[i:]
    if final and rest:
        chunks.append(_Chunk(rest, frame=False, reason="truncated"))
        rest = b""
    return chunks, rest


class _DatagramWriter:
    """File-like sink for pymavlink's ``MAVLink.send``: one datagram per frame, to the current peer."""

    def __init__(self, link: MavlinkLink) -> None:
        self._link = link

    def write(self, buf: bytes) -> None:
        self._link._write(buf)


class MavlinkLink:
    """One MAVLink 2 endpoint: owns the socket (or serial fd), a pymavlink ``MAVLink`` codec and counters.

    ``receive(timeout)`` returns the accepted messages (pymavlink message objects) of what arrived;
    ``send(msg)`` packs (and signs) a message and writes it; the ``*_encode`` builders are on :attr:`mav`.
    """

    def __init__(self, url: str, system_id: int = 245, component_id: int = MAV_COMP_ID_ONBOARD_COMPUTER,
                 target_system: int = 1, baud: int = 921600, signing_key: bytes | None = None,
                 signing_link_id: int = 0, wall_clock: Callable[[], float] = time.time) -> None:
        """``wall_clock``: UTC Unix time [s] for the signing timestamps (a fake one in tests)."""
        self.spec = parse_connection_url(url)
        self.wall_clock = wall_clock
        self.target_system = int(target_system)
        self.counters = LinkCounters()
        #: UDP: :meth:`receive` stops once ``counters.rx_datagrams`` reaches this (None: no limit); a graph beside
        #: a simulator in another process reads exactly the datagrams of one period (fpr_experiments.overlapped)
        self.receive_limit: int | None = None
        self.mav = mavlink.MAVLink(_DatagramWriter(self), srcSystem=int(system_id), srcComponent=int(component_id))
        self.signing = signing_key is not None
        if signing_key is not None:
            enable_signing(self.mav, signing_key, signing_link_id, wall_clock())
        self._sock: socket.socket | None = None
        self._fd: int | None = None
        self._peer: tuple[str, int] | None = None
        self._stream_rest = b""
        self._open(baud)

    # ---- transport ---------------------------------------------------------------------------------------
    def _open(self, baud: int) -> None:
        if self.spec.kind == "serial":
            self._fd = _open_serial(self.spec.device, baud)
            return
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 20)
        if self.spec.kind == "udp_listen":
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            sock.bind((self.spec.host, self.spec.port))
        else:
            sock.bind(("127.0.0.1" if self.spec.host.startswith("127.") else "0.0.0.0", 0))
            self._peer = (self.spec.host, self.spec.port)
        sock.setblocking(False)
        self._sock = sock

    @property
    def local_address(self) -> tuple[str, int] | None:
        """(host, port) the UDP socket is bound to (useful with port 0), None for serial."""
        return self._sock.getsockname() if self._sock is not None else None

    @property
    def peer(self) -> tuple[str, int] | None:
        """Where frames go: the configured ``udpout`` address or the last accepted sender; None before."""
        return self._peer

    def fileno(self) -> int:
        if self._sock is not None:
            return self._sock.fileno()
        assert self._fd is not None
        return self._fd

    def close(self) -> None:
        if self._sock is not None:
            self._sock.close()
            self._sock = None
        if self._fd is not None:
            os.close(self._fd)
            self._fd = None

    def _write(self, buf: bytes) -> None:
        try:
            if self._sock is not None:
                if self._peer is None:
                    return  # no PX4 heard yet: nowhere to send (counted by the caller's `send` result)
                self._sock.sendto(buf, self._peer)
            elif self._fd is not None:
                os.write(self._fd, buf)
            else:
                return
        except OSError:
            self.counters.tx_errors += 1
            return
        self.counters.tx_frames += 1
        self.counters.tx_bytes += len(buf)

    def send(self, msg) -> bool:
        """Pack (sign) and write ``msg``; False when no peer is known yet or the write failed."""
        if self._sock is not None and self._peer is None:
            return False
        before = self.counters.tx_frames
        if self.signing:
            self._update_signing_timestamp()
        self.mav.send(msg)
        return self.counters.tx_frames > before

    def _update_signing_timestamp(self) -> None:
        advance_signing_timestamp(self.mav, self.wall_clock())

    # ---- reception ---------------------------------------------------------------------------------------
    def receive(self, timeout: float = 0.0, max_datagrams: int = 256) -> list:
        """Read what is available (waiting up to ``timeout`` s for the first byte) and return accepted messages.

        Never raises on bad input; socket errors other than "nothing to read" are counted as garbage-free
        transport hiccups and end the read.
        """
        messages: list = []
        fileno = self._sock.fileno() if self._sock is not None else self._fd
        if fileno is None:
            return messages
        if timeout > 0.0:
            try:
                ready, _, _ = select.select([fileno], [], [], timeout)
            except (OSError, ValueError):
                return messages
            if not ready:
                return messages
        if self.receive_limit is not None and self._sock is not None:
            max_datagrams = min(max_datagrams, self.receive_limit - self.counters.rx_datagrams)
        for _ in range(max_datagrams):
            try:
                if self._sock is not None:
                    data, sender = self._sock.recvfrom(_MAX_DATAGRAM)
                else:
                    data, sender = os.read(self._fd, 4096), None
            except (BlockingIOError, InterruptedError):
                break
            except OSError:
                break
            if not data:
                break
            self.counters.rx_datagrams += 1
            self.counters.rx_bytes += len(data)
            messages.extend(self.feed(data, sender))
        return messages

    def _signature_matches(self, frame: bytes) -> bool:
        digest = hashlib.sha256(self.mav.signing.secret_key + frame[:-6]).digest()[:6]
        return hmac.compare_digest(digest, frame[-6:])

    def feed(self, data: bytes, sender: tuple[str, int] | None = None) -> list:
        """Decode one datagram (UDP: ``sender`` given) or one serial chunk; return the accepted messages."""
        stream = self._sock is None
        if stream:
            data = self._stream_rest + bytes(data)
        chunks, rest = split_frames(bytes(data), final=not stream)
        if stream:
            self._stream_rest = rest[-(_HEADER_V2 + 255 + 2 + _SIGNATURE_LEN):]
        accepted = []
        counters = self.counters
        for chunk in chunks:
            if not chunk.frame:
                if chunk.reason == "truncated":
                    counters.rx_truncated += 1
                elif chunk.reason == "bad prefix":
                    counters.rx_bad_bytes += 1
                else:
                    counters.rx_bad_frames += 1
                continue
            if chunk.marker == _MARKER_V1:
                counters.rx_mavlink1 += 1
                if self.signing:
                    counters.rx_unsigned += 1
                    continue
            elif self.signing and not chunk.signed:
                counters.rx_unsigned += 1
                continue
            elif self.signing and not self._signature_matches(chunk.data):
                # checked before pymavlink's decode, which records the stream timestamp before it checks the
                # signature: a forged frame with a future timestamp would otherwise block the genuine stream
                counters.rx_bad_signature += 1
                continue
            try:
                msg = self.mav.decode(bytearray(chunk.data))
            except mavlink.MAVError as error:
                if "signature" in str(error.message).lower():
                    counters.rx_bad_signature += 1
                else:
                    counters.rx_bad_frames += 1
                continue
            except Exception:  # noqa: BLE001 - pymavlink may raise anything on hostile input
                counters.rx_bad_frames += 1
                continue
            if isinstance(msg, mavlink.MAVLink_unknown) or msg.get_type() in ("BAD_DATA", "UNKNOWN"):
                counters.rx_unknown += 1
                continue
            counters.rx_frames += 1
            if msg.get_srcSystem() != self.target_system:
                counters.rx_other_system += 1
            elif sender is not None and self.spec.kind == "udp_listen":
                self._peer = sender
            accepted.append(msg)
        return accepted


def _open_serial(device: str, baud: int) -> int:
    """Open ``device`` raw (8N1, no flow control) at ``baud`` with termios; return the non-blocking fd."""
    import termios
    import tty

    constant = getattr(termios, f"B{int(baud)}", None)
    if constant is None:
        raise ValueError(f"unsupported serial baud rate {baud}")
    fd = os.open(device, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
    try:
        tty.setraw(fd)
        attrs = termios.tcgetattr(fd)
        attrs[4] = attrs[5] = constant  # ispeed, ospeed
        attrs[2] &= ~termios.CRTSCTS
        attrs[2] |= termios.CLOCAL | termios.CREAD
        termios.tcsetattr(fd, termios.TCSANOW, attrs)
    except Exception:
        os.close(fd)
        raise
    return fd
