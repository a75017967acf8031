"""fpr_sim.px4_log: the emulated PX4s' input/mode log written and read back (fault-injection evidence)."""

import math
from types import SimpleNamespace

from fpr_sim.px4_log import Px4Log, read_px4_log


def test_setpoints_and_mode_changes_round_trip_and_disarm_time(tmp_path):
    path = str(tmp_path / "px4_log.csv")
    emulators = [SimpleNamespace(uav_id=1, armed=True, mode_name="OFFBOARD", input_log=None),
                 SimpleNamespace(uav_id=2, armed=True, mode_name="OFFBOARD", input_log=None)]
    log = Px4Log(path, emulators)
    log.sample(0.0)
    emulators[0].input_log(0.01, 1, 1e9, [1.0, 0.0, 0.0, 0.0])  # raw, before validation
    emulators[1].input_log(0.01, 2, 0.42, [1.0, 0.0, 0.0, 0.0])
    log.sample(0.02)  # no change: no row
    emulators[1].mode_name = "AUTO.LOITER"
    log.sample(1.0)
    emulators[1].armed, emulators[1].mode_name = False, "AUTO.LAND (disarmed)"
    log.sample(5.0)
    log.close()
    assert emulators[0].input_log is None
    data = read_px4_log(path)
    assert data.setpoint_thrust[1].tolist() == [1e9] and data.setpoint_thrust[2].tolist() == [0.42]
    assert data.modes[2] == ["OFFBOARD", "AUTO.LOITER", "AUTO.LAND (disarmed)"]
    assert data.armed_at(2, 4.9) and not data.armed_at(2, 5.0)
    assert data.disarm_time(2, after=2.0) == 5.0
    assert math.isnan(data.disarm_time(1, after=2.0))  # never disarmed
