"""px4_protocol: PX4 custom modes, type_mask, SET_ATTITUDE_TARGET packing, and PX4's documented frame values."""

import math

import numpy as np
import pytest
from fpr_model.frames import flu_to_frd, quat_enu_flu_to_ned_frd
from fpr_model.rotations import quat_from_axis_angle

from fpr_px4_bridge import px4_protocol as p


def test_custom_modes_match_px4():
    assert p.CUSTOM_MODE_OFFBOARD == 393216 == 6 << 16
    assert p.CUSTOM_MODE_AUTO_LAND == (4 << 16) | (6 << 24) == 100925440
    mode = p.decode_custom_mode(393216)
    assert (mode.main_mode, mode.sub_mode, mode.name, mode.is_offboard) == (6, 0, "OFFBOARD", True)
    land = p.decode_custom_mode(p.CUSTOM_MODE_AUTO_LAND)
    assert land.name == "AUTO.LAND" and land.is_land and not land.is_offboard
    assert p.decode_custom_mode(p.encode_custom_mode(3)).name == "POSCTL"
    assert p.decode_custom_mode(p.encode_custom_mode(4, 3)).name == "AUTO.LOITER"
    assert p.decode_custom_mode(5 << 16).name == "ACRO"  # the wrong "OFFBOARD = 5" of public scripts
    assert p.decode_custom_mode(200 << 16).name.startswith("UNKNOWN")
    # reserved low bits are ignored
    assert p.decode_custom_mode(393216 | 0x1234).is_offboard
    for main in range(1, 11):
        for sub in range(0, 11):
            d = p.decode_custom_mode(p.encode_custom_mode(main, sub))
            assert (d.main_mode, d.sub_mode) == (main, sub)
    with pytest.raises(ValueError):
        p.encode_custom_mode(256)
    assert p.set_mode_params(6) == (1.0, 6.0, 0.0)


def test_flags_and_type_mask():
    assert p.ATTITUDE_THRUST_TYPE_MASK == 7
    assert (p.THRUST_BODY_SET, p.THROTTLE_IGNORE, p.ATTITUDE_IGNORE) == (32, 64, 128)
    assert p.is_armed(p.MAV_MODE_FLAG_SAFETY_ARMED | p.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED)
    assert not p.is_armed(p.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED)


def _mav():
    mavlink = p.import_mavlink()
    return mavlink, mavlink.MAVLink(None, srcSystem=245, srcComponent=191)


def test_import_helper_sets_mavlink20():
    mavlink, mav = _mav()
    import os

    assert os.environ["MAVLINK20"] == "1"
    assert float(mavlink.WIRE_PROTOCOL_VERSION) == 2.0


def test_level_north_facing_attitude_and_upward_thrust_map_to_px4_values():
    # PX4: q rotates FRD body to NED; level and facing north is the identity; heading east is yaw +90°.
    q_enu_north = quat_from_axis_angle([0.0, 0.0, 1.0], math.pi / 2)  # FLU x axis along ENU y (north)
    np.testing.assert_allclose(quat_enu_flu_to_ned_frd(q_enu_north), [1.0, 0.0, 0.0, 0.0], atol=1e-15)
    q_enu_east = np.array([1.0, 0.0, 0.0, 0.0])  # FLU x along ENU x (east)
    np.testing.assert_allclose(quat_enu_flu_to_ned_frd(q_enu_east),
                               [math.cos(math.pi / 4), 0.0, 0.0, math.sin(math.pi / 4)], atol=1e-15)
    # Upward thrust: body +z in FLU is -z in FRD, i.e. PX4's thrust_body[2] = -thrust (spec §1.3).
    np.testing.assert_allclose(flu_to_frd([0.0, 0.0, 7.5]), [0.0, 0.0, -7.5])
    mavlink, mav = _mav()
    msg = p.encode_set_attitude_target(mav, 1234, 1, 1, q_enu_north, 0.62)
    buf = msg.pack(mav)
    assert buf[0] == 0xFD  # MAVLink 2
    decoded = mavlink.MAVLink(None).decode(bytearray(buf))
    assert decoded.get_type() == "SET_ATTITUDE_TARGET"
    np.testing.assert_allclose(decoded.q, [1.0, 0.0, 0.0, 0.0], atol=1e-7)
    assert decoded.thrust == pytest.approx(0.62)  # positive normalized thrust = upward
    assert decoded.type_mask == 7
    assert (decoded.target_system, decoded.target_component, decoded.time_boot_ms) == (1, 1, 1234)


def test_pack_unpack_round_trip_random_attitudes():
    mavlink, mav = _mav()
    rng = np.random.default_rng(4)
    parser = mavlink.MAVLink(None)
    for _ in range(200):
        q = rng.normal(size=4)
        q /= np.linalg.norm(q)
        thrust = float(rng.uniform(0.0, 1.0))
        buf = p.encode_set_attitude_target(mav, 99, 3, 1, q, thrust).pack(mav)
        target = p.decode_set_attitude_target(parser.decode(bytearray(buf)))
        same = min(np.linalg.norm(target.q_enu_flu - q), np.linalg.norm(target.q_enu_flu + q))
        assert same < 1e-6  # float32 on the wire
        assert target.thrust == pytest.approx(thrust, abs=1e-7)
        assert not target.attitude_ignored and not target.thrust_ignored
        assert target.target_system == 3


@pytest.mark.parametrize(
    "q, thrust",
    [
        ([math.nan, 0, 0, 0], 0.5),
        ([1, 0, 0, math.inf], 0.5),
        ([0.9, 0, 0, 0], 0.5),
        ([0, 0, 0, 0], 0.5),
        ([1, 0, 0], 0.5),
        ([1, 0, 0, 0], math.nan),
        ([1, 0, 0, 0], 1.2),
        ([1, 0, 0, 0], -0.1),
    ],
)
def test_bad_setpoints_are_never_encoded(q, thrust):
    _, mav = _mav()
    with pytest.raises(ValueError):
        p.encode_set_attitude_target(mav, 0, 1, 1, q, thrust)


def test_decode_refuses_invalid_quaternion():
    mavlink, mav = _mav()
    msg = mav.set_attitude_target_encode(time_boot_ms=0, target_system=1, target_component=1, type_mask=7,
                                         q=[0.0, 0.0, 0.0, 0.0], body_roll_rate=0.0, body_pitch_rate=0.0,
                                         body_yaw_rate=0.0, thrust=0.5)
    decoded = mavlink.MAVLink(None).decode(bytearray(msg.pack(mav)))
    with pytest.raises(ValueError):
        p.decode_set_attitude_target(decoded)
