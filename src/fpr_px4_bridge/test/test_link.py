"""MavlinkLink: URLs, framing, signing, and 10,000 random or corrupted datagrams."""

import os
import socket
import time

import pytest
from fpr_px4_bridge.link import (
    MavlinkLink,
    load_signing_key,
    parse_connection_url,
    signing_timestamp,
    split_frames,
)

from fpr_px4_bridge import px4_protocol as p

mavlink = p.import_mavlink()
KEY = bytes(range(32))


def test_connection_urls():
    assert parse_connection_url("udp://127.0.0.1:14541").kind == "udp_listen"
    spec = parse_connection_url("udpout://127.0.0.1:14580")
    assert (spec.kind, spec.host, spec.port) == ("udp_send", "127.0.0.1", 14580)
    assert parse_connection_url("serial:///dev/ttyACM0").device == "/dev/ttyACM0"
    assert parse_connection_url("/dev/ttyUSB1").kind == "serial"
    for bad in ("tcp://1.2.3.4:5", "udp://127.0.0.1", "udpout://127.0.0.1:0", "serial://", "udp://h:99999"):
        with pytest.raises(ValueError):
            parse_connection_url(bad)


def test_signing_key_file(tmp_path):
    hex_file = tmp_path / "key.hex"
    hex_file.write_text(KEY.hex() + "\n")
    assert load_signing_key(str(hex_file)) == KEY
    raw = tmp_path / "key.bin"
    raw.write_bytes(KEY)
    assert load_signing_key(str(raw)) == KEY
    bad = tmp_path / "bad"
    bad.write_text("short")
    with pytest.raises(ValueError):
        load_signing_key(str(bad))


def _frame(system=1, key=None, link_id=0, timestamp=None):
    mav = mavlink.MAVLink(None, srcSystem=system, srcComponent=1)
    if key is not None:
        mav.signing.secret_key = key
        mav.signing.sign_outgoing = True
        mav.signing.link_id = link_id
        mav.signing.timestamp = signing_timestamp() if timestamp is None else timestamp
    msg = p.encode_set_attitude_target(mav, 10, 1, 1, [1.0, 0.0, 0.0, 0.0], 0.5)
    return msg.pack(mav)


def test_split_frames_handles_concatenation_garbage_and_truncation():
    frame = _frame()
    chunks, rest = split_frames(b"\x00\x01" + frame + frame[:7])
    assert [c.frame for c in chunks] == [False, True, False] and rest == b""
    assert chunks[0].reason == "bad prefix" and chunks[2].reason == "truncated"
    chunks, rest = split_frames(frame + frame[:7], final=False)
    assert len(chunks) == 1 and rest == frame[:7]


@pytest.fixture
def listening_link():
    link = MavlinkLink("udp://127.0.0.1:0", system_id=1, target_system=1)
    sender = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sender.bind(("127.0.0.1", 0))
    yield link, sender
    link.close()
    sender.close()


def test_peer_is_learned_from_the_target_system_only(listening_link):
    link, sender = listening_link
    assert link.peer is None and not link.send(link.mav.heartbeat_encode(
        type=18, autopilot=8, base_mode=0, custom_mode=0, system_status=4))
    sender.sendto(_frame(system=7), link.local_address)
    assert len(link.receive(timeout=1.0)) == 1 and link.peer is None
    assert link.counters.rx_other_system == 1
    sender.sendto(_frame(system=1), link.local_address)
    assert len(link.receive(timeout=1.0)) == 1 and link.peer == sender.getsockname()


def test_signing_on_refuses_unsigned_third_party_set_attitude_target():
    receiver = MavlinkLink("udp://127.0.0.1:0", system_id=200, target_system=1, signing_key=KEY)
    third_party = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    third_party.bind(("127.0.0.1", 0))
    try:
        third_party.sendto(_frame(system=1), receiver.local_address)  # unsigned
        assert receiver.receive(timeout=1.0) == []
        assert receiver.counters.rx_unsigned == 1 and receiver.peer is None  # cannot hijack the peer either
        # wrong key, with a timestamp far ahead (must not poison the stream's replay protection)
        third_party.sendto(_frame(system=1, key=bytes(32), timestamp=signing_timestamp() + 10**9),
                           receiver.local_address)
        assert receiver.receive(timeout=1.0) == []
        assert receiver.counters.rx_bad_signature == 1
        good = _frame(system=1, key=KEY)
        third_party.sendto(good, receiver.local_address)
        accepted = receiver.receive(timeout=1.0)
        assert [m.get_type() for m in accepted] == ["SET_ATTITUDE_TARGET"]
        assert receiver.counters.rx_rejected == 2
        third_party.sendto(good, receiver.local_address)  # replay: same timestamp
        assert receiver.receive(timeout=1.0) == [] and receiver.counters.rx_bad_signature == 2
        # outgoing frames are signed (incompat flag 1, 13-byte signature)
        got = []
        receiver.mav.file.write = got.append
        receiver.mav.send(receiver.mav.heartbeat_encode(type=18, autopilot=8, base_mode=0, custom_mode=0,
                                                        system_status=4))
        assert got[0][0] == 0xFD and got[0][2] & 1
    finally:
        receiver.close()
        third_party.close()


def test_fuzz_feed_never_raises_and_counts_garbage(corrupt_datagrams):
    link = MavlinkLink("udp://127.0.0.1:0", system_id=1, target_system=1)
    try:
        accepted = 0
        for data in corrupt_datagrams(10_000):
            accepted += len(link.feed(data, ("127.0.0.1", 9)))
        c = link.counters
        assert c.rx_rejected > 7_000
        assert c.rx_bad_bytes > 0 and c.rx_truncated > 0 and c.rx_bad_frames > 0 and c.rx_unknown > 0
        # whatever got through decoded as a real message (bit flips in e.g. the sequence byte keep the CRC valid)
        assert accepted == c.rx_frames
    finally:
        link.close()


def test_serial_stream_reassembles_frames_across_chunks():
    read_fd, write_fd = os.pipe()
    link = MavlinkLink("udp://127.0.0.1:0", target_system=1)
    link._sock.close()
    link._sock = None
    link._fd = read_fd
    try:
        frame = _frame()
        data = b"\x11" + frame + frame
        out = []
        for i in range(0, len(data), 5):
            out += link.feed(data[i:i + 5])
        assert [m.get_type() for m in out] == ["SET_ATTITUDE_TARGET"] * 2
        assert link.counters.rx_bad_bytes == 1
    finally:
        link.close()
        os.close(write_fd)


def _signed_receiver(timestamp: int):
    """pymavlink with the same key, as PX4 or a GCS would check the frames; ``timestamp``: its own clock."""
    receiver = mavlink.MAVLink(None)
    receiver.signing.secret_key = KEY
    receiver.signing.timestamp = timestamp
    return receiver


def _signing_timestamp_of(frame: bytes) -> int:
    return int.from_bytes(frame[-12:-6], "little")


def test_signing_timestamps_follow_a_fake_wall_clock_and_strictly_increase():
    """MAVLink 2 signing: each outgoing frame carries max(wall-clock timestamp, last + 1), 10 µs units since
    2015-01-01. Fake wall clock: 5 s at 100 frames/s, a jump of 600 s, a burst of 1000 frames in one instant, 5 s
    more; receivers with the same key (one listening throughout, one joining after the jump) accept every frame."""
    sink = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sink.bind(("127.0.0.1", 0))
    sink.settimeout(1.0)
    clock = [1_800_000_000.0]  # Unix time [s] (2027), advanced by hand
    link = MavlinkLink(f"udpout://127.0.0.1:{sink.getsockname()[1]}", system_id=1, component_id=191,
                       target_system=1, signing_key=KEY, signing_link_id=3, wall_clock=lambda: clock[0])
    listener = _signed_receiver(signing_timestamp(clock[0]))
    late = None
    sent: list[tuple[float, int]] = []  # (fake wall time [s], signing timestamp)
    heartbeat = link.mav.heartbeat_encode(type=18, autopilot=8, base_mode=0, custom_mode=0, system_status=4)
    try:
        def send(count: int, step: float) -> None:
            nonlocal late
            for _ in range(count):
                assert link.send(heartbeat)
                frame = sink.recv(65535)
                assert frame[2] & 1 and frame[-13] == 3  # signed, link id 3
                sent.append((clock[0], _signing_timestamp_of(frame)))
                listener.decode(bytearray(frame))
                if late is not None:
                    late.decode(bytearray(frame))
                clock[0] += step

        send(500, 0.01)
        clock[0] += 600.0
        late = _signed_receiver(signing_timestamp(clock[0]))  # a receiver that joins now, on its own clock
        send(1000, 0.0)
        send(500, 0.01)
    finally:
        link.close()
        sink.close()
    stamps = [stamp for _, stamp in sent]
    assert all(b > a for a, b in zip(stamps, stamps[1:], strict=False))  # strictly increasing
    # within 1 s of the (fake) wall clock at every send (the 1000-frame burst runs ahead by 1000 × 10 µs)
    assert max(abs(stamp * 1e-5 - (wall - 1420070400.0)) for wall, stamp in sent) < 1.0
    assert stamps[-1] * 1e-5 + 1420070400.0 == pytest.approx(clock[0], abs=0.05)
    assert listener.signing.goodsig_count == 2000 and listener.signing.badsig_count == 0
    assert late.signing.goodsig_count == 1500 and late.signing.badsig_count == 0


def test_receive_limit_reads_exactly_up_to_the_count_and_keeps_the_rest_queued(listening_link):
    """``receive_limit`` (a graph beside a simulator in another process, fpr_experiments.overlapped): the link reads
    until its datagram count reaches the limit, the rest waits in the socket for a higher limit."""
    link, sender = listening_link
    for _ in range(5):
        sender.sendto(_frame(system=1), link.local_address)
    time.sleep(0.05)
    link.receive_limit = 2
    assert len(link.receive()) == 2 and link.counters.rx_datagrams == 2
    assert link.receive() == [] and link.counters.rx_datagrams == 2  # at its limit: nothing more
    link.receive_limit = 4
    assert len(link.receive()) == 2 and link.counters.rx_datagrams == 4
    link.receive_limit = None
    assert len(link.receive()) == 1 and link.counters.rx_datagrams == 5
