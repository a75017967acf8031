"""BootTimeMapper: time_boot_ms -> local clock."""

import numpy as np
import pytest
from fpr_px4_bridge.bridge import BridgeConfig
from fpr_px4_bridge.time_sync import BootTimeMapper, SimulationBootClock


def test_offset_is_the_least_delayed_sample_and_follows_reboots():
    rng = np.random.default_rng(3)
    mapper = BootTimeMapper(window=50)
    assert mapper.to_local(1.0, fallback=7.0) == 7.0
    offset = 1000.0
    for k in range(200):
        boot = 0.02 * k
        mapper.update(boot, boot + offset + 0.001 + rng.exponential(0.003))
    assert mapper.to_local(10.0, 0.0) == pytest.approx(10.0 + offset + 0.001, abs=1e-3)
    # PX4 reboot: boot time restarts from 0, the offset is re-estimated
    mapper.update(0.0, 2000.0)
    assert mapper.resets == 1 and mapper.offset == pytest.approx(2000.0)
    # the local clock jumps back (simulation restart)
    mapper.update(0.5, 10.0)
    assert mapper.resets == 2 and mapper.offset == pytest.approx(9.5)


def test_window_lets_the_offset_drift_upwards():
    mapper = BootTimeMapper(window=10)
    for k in range(100):
        mapper.update(float(k), float(k) + 1.0 + 0.001 * k)  # receiver clock runs 0.1 % fast
    assert mapper.offset == pytest.approx(1.0 + 0.001 * 90, abs=1e-9)
    with pytest.raises(ValueError):
        BootTimeMapper(window=0)


def test_to_boot_is_the_inverse_of_to_local():
    mapper = BootTimeMapper()
    assert mapper.to_boot(5.0) is None  # no sample yet: the caller falls back
    mapper.update(12.0, 112.5)
    mapper.update(12.1, 112.56)  # least delayed: offset 100.46
    assert mapper.to_boot(112.7) == pytest.approx(12.24)
    assert mapper.to_local(mapper.to_boot(112.7), fallback=0.0) == pytest.approx(112.7)


def test_simulation_boot_clock_is_exact_where_the_estimate_is_biased():
    """A receiver whose /clock lags sees early-looking samples: the estimate shifts, the exact one does not."""
    estimate, exact = BootTimeMapper(), SimulationBootClock()
    for k in range(100):
        boot = 0.01 * k
        received = boot - (0.02 if k % 10 == 3 else 0.0)  # the node's /clock 2 periods behind now and then
        estimate.update(boot, received)
        exact.update(boot, received)
    assert estimate.offset == pytest.approx(-0.02)  # biased by the lag
    assert exact.offset == 0.0 and exact.to_boot(3.21) == 3.21 and exact.to_local(1.5, fallback=0.0) == 1.5


def test_bridge_config_refuses_an_unknown_boot_clock():
    assert BridgeConfig(px4_boot_clock="ros_time").px4_boot_clock == "ros_time"
    with pytest.raises(ValueError, match="px4_boot_clock"):
        BridgeConfig(px4_boot_clock="wall")
