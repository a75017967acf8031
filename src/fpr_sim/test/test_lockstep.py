"""Lockstep of the simulator core (DESIGN.md §5) against scripted MAVLink clients, ROS-free and single-threaded:
the clients' datagrams are queued on the emulators' sockets before the simulation reaches a boundary, so what the
lockstep sees is exact. A setpoint counts for the boundary T_k only when its time_boot_ms (the setpoint's own
instant, on the emulated PX4's boot clock = simulation time) is later than T_{k-1} and than the setpoint that
served T_{k-1}; time_boot_ms = 0 is stamped on arrival (scripted clients, the former behaviour). A live stream is
waited for until it ends as on PX4 (LAND, LOITER, disarm); a stall is a LockstepStalled error, or with
lockstep_on_timeout "continue" a counted timeout."""

import os
import socket

import numpy as np
import pytest

os.environ["MAVLINK20"] = "1"
from fpr_model.frames import quat_enu_flu_to_ned_frd  # noqa: E402
from fpr_px4_bridge.px4_protocol import (  # noqa: E402
    MAV_CMD_DO_SET_MODE,
    Px4AutoSubMode,
    Px4MainMode,
    import_mavlink,
    set_mode_params,
)
from fpr_sim.px4_emulator import boot_time_ms  # noqa: E402
from fpr_sim.scenario import scenario_from_dict  # noqa: E402
from fpr_sim.simulation import LockstepStalled, Simulation, SimulationOptions  # noqa: E402

PERIOD = 0.02  # [s] control period
TIMEOUT = 0.05  # [s] wall: the lockstep's wait (short: the tests provoke timeouts on purpose)


class Controllers:
    """One UDP socket per UAV, sending SET_ATTITUDE_TARGET with a chosen time_boot_ms to its emulator."""

    def __init__(self, sim: Simulation) -> None:
        self.sim = sim
        mavlink = import_mavlink()
        self.mavs = [mavlink.MAVLink(None, srcSystem=200 + i, srcComponent=191) for i in range(sim.n)]
        self.socks = []
        for _ in range(sim.n):
            sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            sock.bind(("127.0.0.1", 0))
            sock.setblocking(False)
            self.socks.append(sock)
        self.targets = [(quat_enu_flu_to_ned_frd(e.quat_local), e.thrust) for e in sim.emulators]

    def send(self, time_boot_ms: int, uavs=None) -> None:
        for i in range(self.sim.n) if uavs is None else uavs:
            q, thrust = self.targets[i]
            msg = self.mavs[i].set_attitude_target_encode(
                time_boot_ms=int(time_boot_ms), target_system=i + 1, target_component=1, type_mask=7,
                q=[float(c) for c in q], body_roll_rate=0.0, body_pitch_rate=0.0, body_yaw_rate=0.0,
                thrust=float(thrust))
            self.socks[i].sendto(msg.pack(self.mavs[i]), ("127.0.0.1", self.sim.ports[i]))

    def land(self, uavs=None) -> None:
        """The bridge's LAND: DO_SET_MODE AUTO.LAND."""
        params = set_mode_params(Px4MainMode.AUTO, Px4AutoSubMode.LAND)
        for i in range(self.sim.n) if uavs is None else uavs:
            msg = self.mavs[i].command_long_encode(i + 1, 1, MAV_CMD_DO_SET_MODE, 0, *params, 0.0, 0.0, 0.0, 0.0)
            self.socks[i].sendto(msg.pack(self.mavs[i]), ("127.0.0.1", self.sim.ports[i]))

    def telemetry_stamps(self, kind: str) -> list[int]:
        parser = import_mavlink().MAVLink(None)
        stamps = []
        for sock in self.socks:
            while True:
                try:
                    data = sock.recv(65535)
                except BlockingIOError:
                    break
                for msg in parser.parse_buffer(data) or []:
                    if msg.get_type() == kind:
                        stamps.append(int(msg.time_boot_ms))
        return stamps

    def close(self) -> None:
        for sock in self.socks:
            sock.close()


def _rig(on_timeout: str):
    """Hovering, armed in OFFBOARD; no ground, no cameras."""
    scenario = scenario_from_dict({"initial_state": {"mode": "hover", "leg_angles": 0.8, "armed": True},
                                   "ground": {"enabled": False}, "cameras": {"enabled": False}})
    sim = Simulation(scenario, SimulationOptions(local_base_port=0, remote_base_port=0, lockstep=True,
                                                 lockstep_timeout=TIMEOUT, lockstep_on_timeout=on_timeout))
    return sim, Controllers(sim)


@pytest.fixture
def rig():
    """A stalled stream is counted and the simulation flies on (lockstep_on_timeout continue)."""
    sim, controllers = _rig("continue")
    yield sim, controllers
    controllers.close()
    sim.close()


@pytest.fixture
def strict_rig():
    """The default: a stalled stream stops the simulation (LockstepStalled)."""
    sim, controllers = _rig("stop")
    yield sim, controllers
    controllers.close()
    sim.close()


def now_ms(sim: Simulation) -> int:
    return boot_time_ms(sim.time)


def fresh_periods(sim, controllers, periods: int, phase: float = 0.0) -> None:
    """A controller per UAV computing on the /clock at each boundary + ``phase`` [s]: setpoints stamped then."""
    for _ in range(periods):
        if phase:
            sim.advance(phase)
        controllers.send(now_ms(sim))
        sim.advance(PERIOD - phase)


def test_fresh_setpoints_every_period_never_time_out_and_arrive_on_time(rig):
    sim, controllers = rig
    fresh_periods(sim, controllers, 10)
    assert sim.lockstep_timeouts == 0
    assert all(e.counters.new_setpoints == 10 for e in sim.emulators)
    # each setpoint was applied at the very boundary it was computed for
    assert sim.setpoint_latency_max() == pytest.approx(0.0, abs=1e-9)


def test_phase_shifted_controllers_serve_the_next_boundary(rig):
    """The controllers' 50 Hz timers need not be aligned with the boundaries."""
    sim, controllers = rig
    fresh_periods(sim, controllers, 10, phase=0.008)
    assert sim.lockstep_timeouts == 0
    assert sim.setpoint_latency_max() == pytest.approx(0.0, abs=1e-9)


def test_repetitions_of_an_old_setpoint_do_not_count(rig):
    """The bridge repeats the last setpoint at 50 Hz with ITS stamp: a stalled controller costs one timeout, then
    the simulation runs on (no wait on a stream of repetitions); a new setpoint is waited for again."""
    sim, controllers = rig
    fresh_periods(sim, controllers, 5)
    stalled_stamp = now_ms(sim) - 20  # the last computed setpoint (boundary 4)
    for _ in range(6):
        controllers.send(stalled_stamp)  # repetitions (twice a period, the bridge's tick and a late one)
        sim.advance(PERIOD / 2)
        controllers.send(stalled_stamp)
        sim.advance(PERIOD / 2)
    assert sim.lockstep_timeouts == 1
    assert all(e.counters.setpoints == 5 + 12 and e.counters.new_setpoints == 5 for e in sim.emulators)
    # the controllers come back: the stream is live again, waited for at each boundary, no more timeouts
    fresh_periods(sim, controllers, 5)
    assert sim.lockstep_timeouts == 1


def test_a_setpoint_computed_before_the_previous_boundary_is_late(rig):
    """A controller behind the simulation: a setpoint stamped T_{k-1} (new, but computed for the previous
    period) does not serve T_k; the wait times out once and the stream stays live."""
    sim, controllers = rig
    fresh_periods(sim, controllers, 3, phase=0.008)  # stamps 8, 28, 48 ms: 48 serves the boundary at 60 ms
    sim.advance(PERIOD)  # boundary 60 ms served; now at 80 ms
    assert sim.lockstep_timeouts == 0 and now_ms(sim) == 80
    controllers.send(60, uavs=[0])  # UAV 1's controller computed on the /clock of 60 ms, delivers only now
    controllers.send(80, uavs=[1, 2])
    sim.advance(PERIOD)  # boundary 80 ms: UAV 1 has nothing later than 60 ms
    assert sim.lockstep_timeouts == 1
    assert sim.emulators[0].counters.new_setpoints == 4
    fresh_periods(sim, controllers, 3)  # still live: waited for, served
    assert sim.lockstep_timeouts == 1 and sim.emulators[0].counters.new_setpoints == 7


def test_zero_time_boot_ms_is_stamped_on_arrival_for_scripted_clients(rig):
    sim, controllers = rig
    for _ in range(10):
        controllers.send(0)
        sim.advance(PERIOD)
    assert sim.lockstep_timeouts == 0
    assert all(e.counters.new_setpoints == 10 for e in sim.emulators)
    assert all(e.setpoint_latency.count == 0 for e in sim.emulators)  # no stamp, no latency sample


def test_a_uav_that_never_streamed_is_not_waited_for(strict_rig):
    """A hover start flies the held hover setpoint until its controllers take over: no waits, no timeouts (the
    pre-arming phase of a ground start likewise)."""
    sim, controllers = strict_rig
    sim.advance(5 * PERIOD)
    assert sim.lockstep_timeouts == 0 and sim.lockstep_waits == 0
    controllers.send(now_ms(sim), uavs=[0, 1])  # UAV 3's controller never starts
    sim.advance(PERIOD)
    fresh_periods(sim, controllers, 3)  # UAV 3 never live, never waited for
    assert sim.lockstep_timeouts == 0


def test_a_stalled_stream_stops_the_simulation_with_one_error_naming_the_uav(strict_rig):
    sim, controllers = strict_rig
    fresh_periods(sim, controllers, 3)
    controllers.send(now_ms(sim), uavs=[0, 2])  # UAV 2's controller dies
    with pytest.raises(LockstepStalled, match=r"from uav2 \(OFFBOARD, last setpoint at 40 ms\) within 0.05 s wall"):
        sim.advance(PERIOD)
    assert sim.lockstep_timeouts == 1


def test_land_ends_the_stream_without_a_timeout(strict_rig):
    """The bridge's LAND arrives with the missing setpoint: the wait re-reads the mode and lets it go."""
    sim, controllers = strict_rig
    fresh_periods(sim, controllers, 3)
    controllers.land(uavs=[1])
    controllers.send(now_ms(sim), uavs=[0, 2])
    sim.advance(PERIOD)
    assert sim.emulators[1].mode_name == "AUTO.LAND" and not sim.emulators[1].takes_offboard_setpoints
    fresh_periods(sim, controllers, 3)  # UAV 2 streams no more, the others do
    assert sim.lockstep_timeouts == 0


def test_telemetry_time_boot_ms_is_the_sample_time(rig):
    """PX4 boots at simulation time 0: the 50 Hz telemetry is stamped with the instant of its sample."""
    sim, controllers = rig
    controllers.send(0)  # contact: the emulators answer the sender
    sim.advance(0.001)
    controllers.telemetry_stamps("ATTITUDE_QUATERNION")
    fresh_periods(sim, controllers, 5)
    stamps = controllers.telemetry_stamps("ATTITUDE_QUATERNION")
    assert len(stamps) == 3 * 5
    assert sorted(set(stamps)) == [20 * k for k in range(1, 6)]
    assert np.all(np.array(stamps) % 20 == 0)


def test_a_client_on_its_own_clock_is_not_waited_for_and_said_once(strict_rig):
    """MAVSDK / MAVROS put their own uptime in time_boot_ms: that link runs free (paced), no stall, one notice."""
    sim, controllers = strict_rig
    notices = []
    sim.on_notice = notices.append
    fresh_periods(sim, controllers, 3)  # on the simulation's clock: waited for
    assert sim.foreign_clock == [False, False, False]
    uptime_ms = 123_456  # the client's clock, far ahead of the simulation's 60 ms
    for k in range(10):
        controllers.send(now_ms(sim), uavs=[0, 2])
        controllers.send(uptime_ms + 20 * k, uavs=[1])
        sim.advance(PERIOD)
    controllers.send(now_ms(sim), uavs=[0, 2])  # UAV 2's client stops: not a stall, it was never waited for
    sim.advance(PERIOD)
    assert sim.foreign_clock == [False, True, False] and sim.lockstep_timeouts == 0
    assert len(notices) == 1 and "uav2" in notices[0] and "123456 ms" in notices[0]


def test_a_stamp_far_behind_the_simulation_is_a_foreign_clock(rig):
    sim, controllers = rig
    sim.advance(7.0)  # a client whose clock started 6 s after the simulator's (its stamps 1 s, the age 6 s)
    controllers.send(now_ms(sim) - 6000, uavs=[0])
    controllers.send(now_ms(sim) - 300, uavs=[1])  # a graph 0.3 s behind at its start: still the simulation's
    controllers.send(now_ms(sim), uavs=[2])
    sim.advance(2 * PERIOD)  # read during the first period, classified at the next boundary
    assert sim.foreign_clock == [True, False, False]


def test_the_wait_hook_is_called_while_waiting_with_the_wall_time_waited(rig):
    """While a boundary waits, Simulation.on_lockstep_wait gets the wall seconds waited so far, increasing, every
    <= 50 ms, up to the watchdog (the simulator node re-publishes /clock from it)."""
    sim, controllers = rig
    waited: list[float] = []
    sim.on_lockstep_wait = waited.append
    fresh_periods(sim, controllers, 3)
    assert all(w < TIMEOUT / 2 for w in waited)  # on time: at most a poll for the datagram in flight
    waited.clear()
    sim.advance(PERIOD)  # the controllers stalled: one wait, to the watchdog
    assert sim.lockstep_timeouts == 1
    assert waited and waited == sorted(waited)  # (TIMEOUT is one poll here)
    assert 0.0 <= waited[0] < 0.05 and waited[-1] <= TIMEOUT + 1e-3
