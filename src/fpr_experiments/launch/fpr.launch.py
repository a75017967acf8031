"""The FPR node graph for ``ros2 launch`` (native ROS 2 Jazzy), from the ONE graph description
(fpr_experiments.graph.describe_graph, also used by the in-process and multi-process runners):

    ros2 launch fpr_experiments fpr.launch.py backend:=sim n:=3 mode:=communicating
    ros2 launch fpr_experiments fpr.launch.py backend:=sim scenario:=hover script:=integration_hover
    ros2 launch fpr_experiments fpr.launch.py backend:=sim realism:=hardware   # + the Wi-Fi link (info_link node)
    ros2 launch fpr_experiments fpr.launch.py backend:=real mode:=communicating   # on the robot (see README)
    ros2 launch fpr_experiments fpr.launch.py backend:=real enclaves:=true       # SROS2 (README, security)

One process per node. With backend:=sim the launch keeps DDS discovery on this host
(ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST) and the simulator's MAVLink is on 127.0.0.1 only; run it under
scripts/isolated.sh to also keep it in a loopback-only network namespace. backend:=real leaves discovery to the
environment (the robot's companion computers talk over Wi-Fi: SUBNET and one ROS_DOMAIN_ID).
"""

from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, OpaqueFunction, SetEnvironmentVariable
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node


def _nodes(context, *args, **kwargs):
    from fpr_experiments.graph import LAUNCH_ARGUMENTS, describe_graph, launch_enclaves, launch_options

    values = {name: LaunchConfiguration(name).perform(context) for name in LAUNCH_ARGUMENTS}
    options = launch_options(values)
    enclaves = launch_enclaves(values)
    # simulation: DDS discovery stays on this host (the robot needs SUBNET: left to its environment)
    environment = [SetEnvironmentVariable("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")] \
        if options.backend == "sim" else []
    nodes = [Node(package=spec.package, executable=spec.executable, name=spec.name,
                  namespace=spec.namespace or None, parameters=[*spec.params_files, dict(spec.parameters)],
                  remappings=[tuple(r) for r in spec.remappings], output="screen",
                  ros_arguments=["--enclave", spec.fully_qualified_name] if enclaves else None)
             for spec in describe_graph(options)]
    return environment + nodes


def generate_launch_description():
    from fpr_experiments.graph import LAUNCH_ARGUMENTS

    arguments = [DeclareLaunchArgument(name, default_value=default, description=text)
                 for name, (default, text) in LAUNCH_ARGUMENTS.items()]
    return LaunchDescription([*arguments, OpaqueFunction(function=_nodes)])
