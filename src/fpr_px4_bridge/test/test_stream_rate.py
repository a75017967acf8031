"""The SET_ATTITUDE_TARGET stream rule (issue 13) with a fake clock: exactly ``stream_rate`` at the peer, no
doubled frames, a new setpoint on the wire within one stream period. The bridge core is driven synchronously on a
real loopback socket; the peer reads after every event, so each frame's send instant is the fake time of the event
that sent it. Nothing here depends on wall time."""

import math
import socket

import numpy as np
import pytest
from fpr_px4_bridge.bridge import BridgeConfig, Px4Bridge
from fpr_px4_bridge.link import MavlinkLink
from fpr_px4_bridge.offboard import OffboardConfig, TeleopMode

from fpr_px4_bridge import px4_protocol as p

mavlink = p.import_mavlink()
ARMED = p.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | p.MAV_MODE_FLAG_SAFETY_ARMED
POSCTL = p.encode_custom_mode(p.Px4MainMode.POSCTL)
Q_LEVEL = (1.0, 0.0, 0.0, 0.0)
RATE = 50.0
T = 1.0 / RATE


class Rig:
    """One bridge (WARMUP: streaming) and a synchronous peer; ``frames``: [(fake send time [s], message)]."""

    def __init__(self, rate: float = RATE, setpoint_timeout: float = 0.25) -> None:
        self.link = MavlinkLink("udp://127.0.0.1:0", system_id=1, target_system=1)
        config = BridgeConfig(uav_id=1, stream_rate=rate, setpoint_timeout=setpoint_timeout,
                              offboard=OffboardConfig(offboard_warmup=1.0))
        self.bridge = Px4Bridge(config, self.link)
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.settimeout(1.0)
        self.mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
        self.parser = mavlink.MAVLink(None)
        self.sock.sendto(self.mav.heartbeat_encode(type=2, autopilot=12, base_mode=ARMED, custom_mode=POSCTL,
                                                   system_status=4).pack(self.mav), self.link.local_address)
        assert self.bridge.poll(0.0, timeout=1.0) == []
        self.bridge.on_teleop(TeleopMode.ARM, 0.0)  # PX4 armed: WARMUP streams (no OFFBOARD request in ARM)
        self.frames: list[tuple[float, object]] = []
        self.submitted: dict[float, float] = {}  # normalized thrust -> submit time [s]

    def close(self) -> None:
        self.link.close()
        self.sock.close()

    def _read(self, now: float, expected: int) -> None:
        for _ in range(expected):
            m = self.parser.decode(bytearray(self.sock.recv(65535)))
            if m.get_type() == "SET_ATTITUDE_TARGET":
                self.frames.append((now, m))

    def _sent(self):
        return self.link.counters.tx_frames

    def tick(self, now: float) -> None:
        before = self._sent()
        self.bridge.tick(now)
        self._read(now, self._sent() - before)

    def submit(self, now: float, k: int, stamp: float | None = None) -> None:
        """Setpoint k submitted at ``now``, stamped ``stamp`` (default: ``now``)."""
        thrust = 5.0 + 0.01 * k  # every setpoint its own thrust, to find it on the wire
        self.submitted[round(self.bridge.normalized_thrust(thrust, now), 6)] = now
        before = self._sent()
        assert self.bridge.submit_setpoint(Q_LEVEL, thrust, 1, now, stamp=now if stamp is None else stamp).accepted
        self._read(now, self._sent() - before)

    def run(self, events) -> None:
        """``events``: [(time [s], order, kind, k)] run in (time, order) order; kind "tick" or "submit"."""
        for now, _, kind, k in sorted(events):
            if kind == "tick":
                self.tick(now)
            else:
                self.submit(now, k)

    def times(self) -> np.ndarray:
        return np.array([t for t, _ in self.frames])

    def first_frame_delays(self) -> list[float]:
        """Per submitted setpoint that reached the wire: first send time − submit time [s]."""
        first: dict[float, float] = {}
        for t, m in self.frames:
            first.setdefault(round(m.thrust, 6), t)
        return [first[key] - t for key, t in self.submitted.items() if key in first]

    def doubled(self) -> int:
        """Frames carrying the same setpoint as the frame before them."""
        return sum(1 for (_, a), (_, b) in zip(self.frames, self.frames[1:], strict=False)
                   if (a.time_boot_ms, a.thrust) == (b.time_boot_ms, b.thrust))


@pytest.fixture
def rig():
    made: list[Rig] = []

    def make(**kwargs) -> Rig:
        made.append(Rig(**kwargs))
        return made[-1]

    yield make
    for r in made:
        r.close()


def _ticks(duration: float, period: float = T, late=None):
    """Stream-timer ticks k·period (+ a lateness per tick: timers fire late, never early)."""
    n = int(round(duration / period))
    return [(round(k * period + (0.0 if late is None else late[k]), 9), 0, "tick", k) for k in range(n)]


@pytest.mark.parametrize("phase, order", [(0.0, -1), (0.0, 1), (0.0005, 0), (0.007, 0), (0.0195, 0)])
def test_controller_at_the_stream_rate_each_setpoint_once_at_once(rig, phase, order):
    """50 Hz setpoints at any phase against the 50 Hz tick, also in the same instant (submit before: order -1,
    after: order 1, as the simulation's executor may run them): one frame per period, each setpoint sent once,
    at its submission, never repeated."""
    r = rig()
    duration = 5.0
    submits = [(round(k * T + phase, 9), order, "submit", k) for k in range(int(duration / T))]
    r.run(_ticks(duration) + submits)
    times = r.times()
    assert len(times) == len(submits)
    assert r.doubled() == 0 and r.bridge.repetitions_sent == 0
    assert max(r.first_frame_delays()) == 0.0  # sent in the instant it was submitted
    np.testing.assert_allclose(np.diff(times), T, atol=1e-9)
    assert (len(times) - 1) / (times[-1] - times[0]) == pytest.approx(RATE, rel=1e-6)


@pytest.mark.parametrize("order", [-1, 1])
@pytest.mark.parametrize("lateness", [0.0045, 0.008, 0.009])
def test_one_late_tick_with_its_controller_does_not_hold_later_setpoints(rig, lateness, order):
    """A loaded machine on the wall clock (seen in CI): ONE tick and the controller's setpoint of the same period
    both run late (the setpoint stamped when it ran), every other one on the grid k T. Each setpoint must still
    leave at its submission. (The former slot rule, a new slot only 0.6 T after the tick that opened the current
    one, held every later setpoint after a tick late by more than 0.4 T.) Later than 0.5 T, the late setpoint and
    the next one are two setpoints within one period: thinned, as from a faster controller."""
    r = rig()
    duration, late_k = 1.0, 12
    n = int(round(duration / T))
    late = np.zeros(n)
    late[late_k] = lateness
    submits = [(round(k * T + late[k], 9), order, "submit", k) for k in range(n)]
    r.run(_ticks(duration, late=late) + submits)
    assert max(r.first_frame_delays()) == 0.0 and len(r.first_frame_delays()) == n
    assert len(r.times()) == n and r.bridge.repetitions_sent == 0


@pytest.mark.parametrize("order", [-1, 1])
@pytest.mark.parametrize("lateness", [0.0045, 0.01, 0.015, 0.019, 0.025, 0.035])
def test_simulation_time_a_setpoint_arriving_late_never_holds_the_next_ones(rig, lateness, order):
    """Simulation time (the lockstep): the controller stamps each setpoint with the /clock it computed on, k T;
    one setpoint reaches the bridge late, after the bridge's clock moved on by ``lateness`` (up to beyond the
    next period's tick). It and every later setpoint leave at their submission: the simulation's lockstep waits
    for each period's setpoint before the clock moves on, so one held setpoint stalls the graph until the lockstep
    watchdog, and (before the slots followed the setpoints' own instants) every later one was held in turn: the
    tick that sent the held setpoint filled the next slot, so the next setpoint was held, and so on (a 24 s fault
    flight: 331 periods waited for the watchdog)."""
    r = rig()
    duration, late_k = 1.0, 12
    n = int(round(duration / T))
    events = _ticks(duration)
    for k in range(n):
        now = round(k * T + (lateness if k == late_k else 0.0), 9)
        events.append((now, order, "submit_stamped", k))
    for now, _, kind, k in sorted(events):
        if kind == "tick":
            r.tick(now)
        else:
            r.submit(now, k, stamp=k * T)
    delays = r.first_frame_delays()
    assert len(delays) == n and max(delays) == 0.0
    assert r.doubled() == r.bridge.repetitions_sent
    assert r.bridge.repetitions_sent <= 1  # the period whose setpoint was late may be topped up


@pytest.mark.parametrize("phase", [0.0, 0.001, 0.01, 0.019])
def test_jittered_controller_and_late_ticks_keep_the_rate_exact_and_the_delay_within_one_period(rig, phase):
    """Submission jitter of ±4 ms and tick lateness of 0-2 ms (seeded): the number of frames is the number of
    periods, a new setpoint leaves within one period, and repetitions (the only frames that carry a setpoint
    twice) happen only in a period that got no new setpoint."""
    r = rig()
    rng = np.random.default_rng(13)
    duration = 10.0
    n = int(round(duration / T))
    late = rng.uniform(0.0, 0.002, n)
    jitter = rng.uniform(-0.004, 0.004, n)
    submits = [(round(k * T + phase + jitter[k], 9), 0, "submit", k) for k in range(1, n - 1)]
    r.run(_ticks(duration, late=late) + submits)
    times = r.times()
    # one frame per tick period from the first setpoint's period to the last closed one: exactly stream_rate
    assert len(times) in (n - 2, n - 1)
    delays = r.first_frame_delays()
    assert len(delays) >= len(submits) - 2 and max(delays) <= T + 0.002 + 1e-9  # the next tick, late by <= 2 ms
    assert r.doubled() == r.bridge.repetitions_sent <= 0.05 * n
    assert np.diff(times).min() >= 0.0


def test_slower_controller_is_topped_up_to_the_stream_rate(rig):
    """25 Hz setpoints: every other period carries a repetition; the rate at the peer stays 50 Hz."""
    r = rig()
    duration = 4.0
    submits = [(round(k * 2 * T + 0.005, 9), 0, "submit", k) for k in range(int(duration / (2 * T)))]
    r.run(_ticks(duration) + submits)
    times = r.times()
    assert (len(times) - 1) / (times[-1] - times[0]) == pytest.approx(RATE, rel=0.02)
    assert r.bridge.repetitions_sent == pytest.approx(len(submits), abs=1)
    # new setpoints at once; the top-up closes the empty period, so the gap before it is < 2 periods
    assert max(r.first_frame_delays()) == 0.0 and np.diff(times).max() <= 2 * T - 0.005 + 1e-9


def test_faster_controller_is_thinned_to_the_stream_rate_and_the_newest_setpoint_wins(rig):
    """100 Hz setpoints: 50 frames per second, never two in a period, each within one period of its submission."""
    r = rig()
    duration = 4.0
    submits = [(round(k * T / 2 + 0.003, 9), 0, "submit", k) for k in range(int(duration / (T / 2)))]
    r.run(_ticks(duration) + submits)
    times = r.times()
    assert len(times) == pytest.approx(duration * RATE, abs=1)
    assert r.doubled() == 0 and max(r.first_frame_delays()) <= T + 1e-9
    assert np.diff(times).min() >= T / 2 - 1e-9


def test_a_faster_tick_caller_does_not_speed_the_stream_up(rig):
    """Ticks at 100 Hz: one setpoint, then repetitions at exactly 50 Hz until setpoint_timeout. The slots are
    centred on the setpoint's instant 0, [-T/2, T/2), [T/2, 3T/2), ...: the first repetition closes the first slot
    without a new setpoint, at 3T/2."""
    r = rig(setpoint_timeout=1.0)
    r.submit(0.0, 0)
    r.run(_ticks(0.9, period=T / 2))
    times = r.times()
    assert times[0] == 0.0 and times[1] == pytest.approx(1.5 * T)
    np.testing.assert_allclose(np.diff(times[1:]), T, atol=1e-9)
    assert len(times) == 45 and r.bridge.repetitions_sent == 44  # 0, then 1.5 T, 2.5 T, ... 0.89 s


def test_stalled_controller_repetitions_at_the_rate_then_stop_after_setpoint_timeout(rig):
    r = rig(setpoint_timeout=0.25)
    submits = [(round(k * T + 0.004, 9), 0, "submit", k) for k in range(25)]  # until 0.484 s
    r.run(_ticks(2.0) + submits)
    times = r.times()
    assert np.diff(times).max() <= 2 * T + 1e-9  # the first repetition: at the end of the first empty period
    np.testing.assert_allclose(np.diff(times[times > 0.5]), T, atol=1e-9)
    assert 0.484 + 0.25 - T <= times[-1] <= 0.484 + 0.25 + 1e-9


def test_setpoints_outside_the_streaming_states_are_never_sent_and_the_first_one_goes_at_once(rig):
    r = rig()
    r.bridge.on_teleop(TeleopMode.IDLE, 0.0)
    r.run(_ticks(0.2) + [(0.005 + k * T, 0, "submit", k) for k in range(10)])
    assert r.frames == []
    r.bridge.on_teleop(TeleopMode.ARM, 0.2)
    r.submit(0.205, 100)
    assert len(r.frames) == 1 and r.frames[0][0] == 0.205
    assert math.isclose(r.frames[0][1].thrust, r.bridge.normalized_thrust(6.0, 0.205), abs_tol=1e-6)
