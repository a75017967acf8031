"""Test helpers of fpr_px4_bridge: a fake PX4 on 127.0.0.1 (pymavlink over a UDP socket of its own).

The fake answers like PX4 does for what the bridge uses: HEARTBEAT (armed flag, custom_mode), COMMAND_LONG
ARM/DISARM and DO_SET_MODE with COMMAND_ACK (OFFBOARD refused unless setpoints arrived in the last 0.5 s, as
PX4's proof-of-life rule), and telemetry (ATTITUDE_QUATERNION, HIGHRES_IMU, ODOMETRY, SYS_STATUS).
Every received SET_ATTITUDE_TARGET and COMMAND_LONG is recorded with its arrival time on the fake's clock.

Clock: wall time (``time.monotonic()``) by default, the fake paces itself in its thread. With ``clock=`` (a
callable returning simulation time [s]) the test paces it: :meth:`FakePx4.emit_due` sends what is due at that
time (HEARTBEATs, telemetry), the thread only receives; its boot clock is then the simulation clock
(``time_boot_ms`` = simulation time), like the simulator's PX4 emulator.
"""

from __future__ import annotations

import os
import socket
import sys
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import pytest

_PACKAGE_ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
for _path in (_PACKAGE_ROOT, os.path.join(os.path.dirname(_PACKAGE_ROOT), "fpr_model")):
    if _path not in sys.path:
        sys.path.insert(0, _path)

from fpr_px4_bridge import px4_protocol as p  # noqa: E402

mavlink = p.import_mavlink()


def free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


@dataclass
class Received:
    t: float
    msg: object


class _Writer:
    def __init__(self, fake: FakePx4) -> None:
        self.fake = fake

    def write(self, buf: bytes) -> None:
        self.fake.sock.sendto(buf, self.fake.bridge_address)


class FakePx4:
    """A PX4 stand-in talking MAVLink 2 over UDP to a bridge listening at ``bridge_address``."""

    def __init__(self, bridge_address, system_id: int = 1, signing_key: bytes | None = None,
                 heartbeat_rate: float = 10.0, telemetry_rate: float = 20.0,
                 clock: Callable[[], float] | None = None) -> None:
        self.bridge_address = bridge_address
        self.self_paced = clock is None
        self.clock = time.monotonic if clock is None else clock
        self._boot: float | None = None if clock is None else 0.0  # simulation: boot clock = simulation clock
        self._next_hb: float | None = None
        self._next_tel: float | None = None
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.settimeout(0.02)
        self.mav = mavlink.MAVLink(_Writer(self), srcSystem=system_id, srcComponent=1)
        if signing_key is not None:
            self.mav.signing.secret_key = signing_key
            self.mav.signing.sign_outgoing = True
            self.mav.signing.timestamp = int((time.time() - 1420070400) * 100000)
        self.heartbeat_rate = heartbeat_rate
        self.telemetry_rate = telemetry_rate
        self.armed = False
        self.custom_mode = p.encode_custom_mode(p.Px4MainMode.POSCTL)
        self.voltage_mv = 12000
        self.attitude_ned = [1.0, 0.0, 0.0, 0.0]
        self.send_heartbeats = True
        self.setpoints: list[Received] = []
        self.commands: list[Received] = []
        self.other: list[Received] = []
        self.lock = threading.Lock()
        self._running = False
        self._thread: threading.Thread | None = None
        self._send_lock = threading.Lock()

    # ---- control -----------------------------------------------------------------------------------------
    def start(self) -> FakePx4:
        self._running = True
        self._thread = threading.Thread(target=self._loop, daemon=True)
        self._thread.start()
        return self

    def stop(self) -> None:
        self._running = False
        if self._thread is not None:
            self._thread.join(timeout=2.0)
        self.sock.close()

    def send(self, msg) -> None:
        with self._send_lock:
            self.mav.send(msg)

    def send_raw(self, data: bytes) -> None:
        self.sock.sendto(data, self.bridge_address)

    def setpoint_times(self) -> list[float]:
        with self.lock:
            return [r.t for r in self.setpoints]

    def command_list(self) -> list[Received]:
        with self.lock:
            return list(self.commands)

    # ---- PX4 behaviour -------------------------------------------------------------------------------------
    def _heartbeat(self) -> None:
        base = p.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | (p.MAV_MODE_FLAG_SAFETY_ARMED if self.armed else 0)
        self.send(self.mav.heartbeat_encode(type=p.MAV_TYPE_QUADROTOR, autopilot=p.MAV_AUTOPILOT_PX4,
                                            base_mode=base, custom_mode=self.custom_mode,
                                            system_status=p.MAV_STATE_ACTIVE))

    def _telemetry(self, boot_ms: int) -> None:
        q = self.attitude_ned
        self.send(self.mav.attitude_quaternion_encode(time_boot_ms=boot_ms, q1=q[0], q2=q[1], q3=q[2], q4=q[3],
                                                      rollspeed=0.1, pitchspeed=-0.2, yawspeed=0.3))
        self.send(self.mav.highres_imu_encode(time_usec=boot_ms * 1000, xacc=0.5, yacc=0.25, zacc=-9.81,
                                              xgyro=0.1, ygyro=-0.2, zgyro=0.3, xmag=0.0, ymag=0.0, zmag=0.0,
                                              abs_pressure=0.0, diff_pressure=0.0, pressure_alt=0.0,
                                              temperature=20.0, fields_updated=0))
        self.send(self.mav.odometry_encode(time_usec=boot_ms * 1000, frame_id=1, child_frame_id=12, x=0.0, y=0.0,
                                           z=0.0, q=q, vx=1.0, vy=2.0, vz=-0.5, rollspeed=0.1, pitchspeed=-0.2,
                                           yawspeed=0.3, pose_covariance=[float("nan")] * 21,
                                           velocity_covariance=[float("nan")] * 21))
        self.send(self.mav.sys_status_encode(
            onboard_control_sensors_present=0, onboard_control_sensors_enabled=0, onboard_control_sensors_health=0,
            load=0, voltage_battery=self.voltage_mv, current_battery=1500, battery_remaining=80, drop_rate_comm=0,
            errors_comm=0, errors_count1=0, errors_count2=0, errors_count3=0, errors_count4=0))

    def _on_command(self, msg) -> None:
        result = p.MAV_RESULT_ACCEPTED
        if msg.command == p.MAV_CMD_COMPONENT_ARM_DISARM:
            self.armed = msg.param1 > 0.5
        elif msg.command == p.MAV_CMD_DO_SET_MODE:
            main, sub = int(msg.param2), int(msg.param3)
            recent = self.setpoints and self.clock() - self.setpoints[-1].t < 0.5
            if main == p.Px4MainMode.OFFBOARD and not recent:
                result = 1  # TEMPORARILY_REJECTED: no offboard proof of life
            else:
                self.custom_mode = p.encode_custom_mode(main, sub)
        self.send(self.mav.command_ack_encode(command=msg.command, result=result))

    def emit_due(self) -> None:
        """Send the HEARTBEATs and telemetry due at ``clock()`` (called by the thread when self-paced)."""
        now = self.clock()
        if self._next_hb is None or self._next_tel is None:
            self._next_hb = self._next_tel = now
            self._boot = now if self._boot is None else self._boot
        if now >= self._next_hb:
            self._next_hb += 1.0 / self.heartbeat_rate
            if self.send_heartbeats:
                self._heartbeat()
        if now >= self._next_tel and self.telemetry_rate > 0:
            self._next_tel += 1.0 / self.telemetry_rate
            self._telemetry(int(round((now - self._boot) * 1000)))

    def _loop(self) -> None:
        parser = mavlink.MAVLink(None)
        parser.robust_parsing = True
        while self._running:
            if self.self_paced:
                self.emit_due()
            try:
                data, _ = self.sock.recvfrom(65535)
            except (TimeoutError, OSError):
                continue
            t = self.clock()
            try:
                msgs = parser.parse_buffer(data) or []
            except Exception:  # noqa: BLE001
                continue
            for msg in msgs:
                kind = msg.get_type()
                with self.lock:
                    if kind == "SET_ATTITUDE_TARGET":
                        self.setpoints.append(Received(t, msg))
                    elif kind == "COMMAND_LONG":
                        self.commands.append(Received(t, msg))
                    else:
                        self.other.append(Received(t, msg))
                if kind == "COMMAND_LONG":
                    self._on_command(msg)


def corrupt_datagram_stream(count: int, seed: int = 7):
    rng = np.random.default_rng(seed)
    mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    templates = [
        p.encode_set_attitude_target(mav, 10, 1, 1, [1.0, 0.0, 0.0, 0.0], 0.5).pack(mav),
        mav.heartbeat_encode(type=2, autopilot=12, base_mode=129, custom_mode=393216, system_status=4).pack(mav),
        mav.command_ack_encode(command=400, result=0).pack(mav),
        mav.attitude_quaternion_encode(time_boot_ms=5, q1=1.0, q2=0.0, q3=0.0, q4=0.0, rollspeed=0.0,
                                       pitchspeed=0.0, yawspeed=0.0).pack(mav),
    ]
    for i in range(count):
        kind = i % 5
        if kind == 0:  # pure random bytes, sometimes starting with a MAVLink marker
            data = bytearray(rng.integers(0, 256, size=int(rng.integers(1, 300)), dtype=np.uint8).tobytes())
            if rng.random() < 0.5:
                data[0] = 0xFD if rng.random() < 0.7 else 0xFE
        else:
            data = bytearray(templates[int(rng.integers(len(templates)))])
            if kind == 1:  # bit flips
                for _ in range(int(rng.integers(1, 4))):
                    data[int(rng.integers(len(data)))] ^= 1 << int(rng.integers(8))
            elif kind == 2:  # truncation
                data = data[: int(rng.integers(1, len(data)))]
            elif kind == 3:  # unknown message id with a valid-looking header
                data[7], data[8], data[9] = 0xEE, 0xEE, 0x00
            else:  # bad length / incompat flags
                data[1 + int(rng.integers(2))] = int(rng.integers(256))
        yield bytes(data)


@pytest.fixture
def free_port() -> int:
    """A UDP port free on 127.0.0.1 right now."""
    return free_udp_port()


@pytest.fixture
def corrupt_datagrams():
    """``corrupt_datagrams(count, seed)``: random bytes, bit flips, truncations, unknown ids, bad headers."""
    return corrupt_datagram_stream


@pytest.fixture
def fake_px4_factory():
    fakes: list[FakePx4] = []

    def make(bridge_address, **kwargs) -> FakePx4:
        fake = FakePx4(bridge_address, **kwargs)
        fakes.append(fake)
        return fake

    yield make
    for fake in fakes:
        fake.stop()
