"""One filled, non-default sample of every fpr_msgs message type (shared by the round-trip test and its publisher)."""
import math
from collections.abc import Callable

from geometry_msgs.msg import Point, Pose, Quaternion, Twist, Vector3
from std_msgs.msg import Header

from fpr_msgs.msg import (
    AttitudeThrustSetpoint,
    ControllerStatus,
    FprState,
    InformationVector,
    LocalState,
    MarkerDetection,
    TeleopCommand,
    UavStatus,
    WrenchEstimate,
)


def _header(frame: str) -> Header:
    header = Header(frame_id=frame)
    header.stamp.sec, header.stamp.nanosec = 12, 345_000_000
    return header


def _quat() -> Quaternion:
    return Quaternion(x=0.1, y=-0.2, z=0.3, w=math.sqrt(1 - 0.14))


def _pose(x: float) -> Pose:
    return Pose(position=Point(x=x, y=2.0, z=-3.0), orientation=_quat())


def information_vector() -> InformationVector:
    return InformationVector(header=_header('flat_platform'), uav_id=2, leg_angle=0.9,
                             velocity=Vector3(x=0.1, y=0.2, z=-0.3), attitude=_quat(), thrust=12.5, valid=True)


def teleop_command() -> TeleopCommand:
    return TeleopCommand(header=_header(''), mode=TeleopCommand.MODE_FLY,
                         platform_velocity=Vector3(x=0.2, y=-0.1, z=0.05), yaw_rate=0.1, roll=0.05, pitch=-0.02,
                         leg_angles=[0.8, 0.9, 1.0], platform_acceleration=Vector3(x=0.01, y=0.0, z=0.0),
                         yaw_acceleration=0.0, roll_rate=0.01, pitch_rate=-0.01, leg_rates=[0.0, 0.1, 0.0],
                         contact_force=5.0)


def attitude_thrust_setpoint() -> AttitudeThrustSetpoint:
    return AttitudeThrustSetpoint(header=_header('uav1/local_enu'), uav_id=1, attitude=_quat(), thrust=11.3)


def marker_detection() -> MarkerDetection:
    return MarkerDetection(header=_header('uav1/camera_optical'), marker_id=0, pose=_pose(0.5),
                           reprojection_error=0.4, ambiguity_ratio=7.5,
                           corners=[float(v) for v in range(100, 108)], marker_size=0.109)


def local_state() -> LocalState:
    return LocalState(header=_header('uav3/platform'), uav_id=3, relative_pose=_pose(-0.4), leg_angle=1.0,
                      platform_roll=0.05, platform_pitch=-0.04, uav_attitude_flat=_quat(),
                      uav_velocity_flat=Vector3(x=0.3, y=0.0, z=0.1),
                      uav_angular_velocity=Vector3(x=0.01, y=0.02, z=0.03), relative_yaw=2.1, uav_yaw=-0.5,
                      pose_stddev=[0.01, 0.01, 0.02, 0.01, 0.01, 0.03], detection_age=0.05,
                      rejected_detections=4, valid=True)


def wrench_estimate() -> WrenchEstimate:
    return WrenchEstimate(header=_header(''), uav_id=1, observer='fowo',
                          platform_force=Vector3(x=0.1, y=0.0, z=-2.9), platform_moment=Vector3(x=0.0, y=0.2, z=0.0),
                          leg_moments=[0.1, -0.2, 0.3], contact_force=4.9)


def uav_status() -> UavStatus:
    return UavStatus(header=_header(''), uav_id=2, state=UavStatus.STATE_OFFBOARD, connected=True, armed=True,
                     offboard=True, failsafe=False, px4_custom_mode=393216, mode_name='OFFBOARD',
                     battery_voltage=11.9, battery_remaining=0.8, link_age=0.2, setpoint_rate=50.0,
                     rx_garbage=3, rejected_setpoints=1)


def fpr_state() -> FprState:
    return FprState(header=_header('world'), platform_pose=_pose(1.0),
                    platform_twist=Twist(linear=Vector3(x=0.1, y=0.0, z=0.0), angular=Vector3(x=0.0, y=0.0, z=0.2)),
                    leg_angles=[1.0, 1.1, 1.2], leg_rates=[0.0, 0.0, 0.1],
                    uav_poses=[_pose(2.0), _pose(3.0), _pose(4.0)],
                    uav_velocities=[Vector3(x=float(i), y=0.0, z=0.0) for i in range(3)],
                    uav_thrusts=[11.0, 11.5, 12.0], external_wrench=[0.0] * 8 + [-2.9],
                    contact_force=0.0, payload_mass=0.3, battery_voltages=[12.1, 12.0, 11.9])


def controller_status() -> ControllerStatus:
    return ControllerStatus(header=_header('world'), uav_id=1, configured_mode=ControllerStatus.MODE_COMMUNICATING,
                            active_mode=ControllerStatus.MODE_NON_COMMUNICATING, fallback_active=True,
                            info_ages=[0.0, 0.02, 0.5], thrust_saturated=False, tilt_saturated=True,
                            local_state_valid=True, loop_time=0.0004,
                            desired_position=Vector3(x=0.3, y=-0.2, z=1.1), desired_roll=0.05, desired_pitch=-0.03,
                            desired_yaw=1.2, desired_leg_angles=[0.8, 0.85, 0.9], desired_contact_force=5.0)


SAMPLES: dict[str, Callable[[], object]] = {
    'InformationVector': information_vector,
    'TeleopCommand': teleop_command,
    'AttitudeThrustSetpoint': attitude_thrust_setpoint,
    'MarkerDetection': marker_detection,
    'LocalState': local_state,
    'WrenchEstimate': wrench_estimate,
    'UavStatus': uav_status,
    'FprState': fpr_state,
    'ControllerStatus': controller_status,
}
