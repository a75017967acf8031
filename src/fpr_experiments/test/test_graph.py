"""The graph description: the node list, its parameters as rcl applies them, and name resolution."""

from __future__ import annotations

import importlib.metadata

import pytest
from fpr_experiments.graph import (
    EXECUTABLES,
    GraphOptions,
    NodeSpec,
    describe_graph,
    groups,
    parameter_value_text,
    read_graph_file,
    write_graph_file,
)
from fpr_experiments.node_factory import NODE_CLASSES
from fpr_experiments.resources import JOY_SCRIPTS, SCENARIOS, UnknownNameError


def test_sim_graph_has_the_simulator_four_nodes_per_uav_and_the_ground_station():
    specs = describe_graph(GraphOptions(n=3, mode="impedance", cameras="images"))
    names = [s.fully_qualified_name for s in specs]
    assert names[0] == "/simulator"
    for i in (1, 2, 3):
        for node in ("px4_bridge", "aruco_detector", "pose_estimator", "controller"):
            assert f"/fpr/uav{i}/{node}" in names
    assert "/fpr/ground/teleop" in names and "/fpr/ground/joy_script" in names
    assert list(groups(specs)) == ["simulator", "uav1", "uav2", "uav3", "ground"]
    assert all(s.parameters["use_sim_time"] is True for s in specs if s.executable != "simulator")
    assert "use_sim_time" not in specs[0].parameters  # the simulator is the clock, it does not read /clock
    controllers = [s for s in specs if s.executable == "controller"]
    assert [(c.parameters["uav_id"], c.parameters["mode"], c.parameters["n"]) for c in controllers] == [
        (1, "impedance", 3), (2, "impedance", 3), (3, "impedance", 3)]
    simulator = specs[0]
    assert simulator.parameters["emulated_cameras"] is False
    assert simulator.parameters["scenario_file"] == SCENARIOS.resolve("ground_start")


def test_emulated_cameras_need_no_detector_and_the_real_robot_has_no_simulator_nor_sim_time():
    emulated = describe_graph(GraphOptions(cameras="emulated"))
    assert not any(s.executable == "aruco_detector" for s in emulated)
    real = describe_graph(GraphOptions(backend="real", cameras="images", operator="joystick"))
    assert not any(s.executable == "simulator" for s in real)
    assert all("use_sim_time" not in s.parameters for s in real)
    assert [s.executable for s in real if s.group == "ground"] == ["teleop", "joystick"]
    with pytest.raises(ValueError, match="emulated"):
        describe_graph(GraphOptions(backend="real", cameras="emulated"))


def test_overrides_apply_per_executable_then_per_uav():
    specs = describe_graph(GraphOptions(parameters={"controller": {"observer": "sowo"}},
                                        uav_parameters={("controller", 2): {"observer": "smwo"}},
                                        params_files={"controller": ["/tmp/extra.yaml"]}))
    controllers = {s.uav_id: s for s in specs if s.executable == "controller"}
    assert [controllers[i].parameters["observer"] for i in (1, 2, 3)] == ["sowo", "smwo", "sowo"]
    assert controllers[1].params_files[-1] == "/tmp/extra.yaml"
    with pytest.raises(ValueError, match="unknown executable"):
        describe_graph(GraphOptions(parameters={"controler": {}}))


def test_ros_args_are_what_ros2_run_would_get():
    spec = NodeSpec("fpr_control", "controller", "controller", "/fpr/uav1", "uav1", ["/a.yaml"],
                    {"uav_id": 1, "mode": "impedance", "gains.x": [1.0, 2.0], "flag": True}, [("a", "b")])
    assert spec.ros_args() == ["--ros-args", "-r", "__node:=controller", "-r", "__ns:=/fpr/uav1",
                               "--params-file", "/a.yaml", "-p", "uav_id:=1", "-p", 'mode:="impedance"',
                               "-p", "gains.x:=[1.0, 2.0]", "-p", "flag:=true", "-r", "a:=b"]
    assert spec.command()[:4] == ["ros2", "run", "fpr_control", "controller"]
    assert parameter_value_text(float("nan")) == ".nan" and parameter_value_text("true") == '"true"'


def test_graph_file_round_trip(tmp_path):
    specs = describe_graph(GraphOptions(cameras="images", info_link=True))
    write_graph_file(specs, str(tmp_path / "graph.json"))
    assert read_graph_file(str(tmp_path / "graph.json")) == specs
    assert any(s.executable == "info_link" for s in specs)
    assert [s.parameters["info_input_topic"] for s in specs if s.executable == "controller"] == [
        "/fpr/uav1/info_link", "/fpr/uav2/info_link", "/fpr/uav3/info_link"]


def test_realism_reaches_the_simulator_and_the_info_link():
    ideal = describe_graph(GraphOptions())  # the scenario's own profile: ideal, no link model, no outage
    assert ideal[0].parameters["realism"] == "ideal"
    assert not any(s.executable == "info_link" for s in ideal)
    assert all("info_input_topic" not in s.parameters for s in ideal if s.executable == "controller")
    hardware = describe_graph(GraphOptions(realism="hardware"))  # its link model needs the info_link node
    link = next(s for s in hardware if s.executable == "info_link")
    assert hardware[0].parameters["realism"] == link.parameters["realism"] == "hardware"
    assert link.parameters["scenario_file"] == hardware[0].parameters["scenario_file"]
    assert link.parameters["output_topic"] == "/fpr/uav{uav}/info_link" and link.group == "link"
    assert [s.parameters["info_input_topic"] for s in hardware if s.executable == "controller"] == [
        "/fpr/uav1/info_link", "/fpr/uav2/info_link", "/fpr/uav3/info_link"]
    outage = describe_graph(GraphOptions(realism="ideal", info_link=True))  # an outage alone needs it too
    assert next(s for s in outage if s.executable == "info_link").parameters["realism"] == "ideal"


def test_realism_is_validated_and_the_robot_has_none():
    with pytest.raises(ValueError, match="realism 'rough' is not one of ideal, hardware"):
        describe_graph(GraphOptions(realism="rough"))
    for options in (GraphOptions(backend="real", cameras="images", realism="hardware"),
                    GraphOptions(backend="real", cameras="images", info_link=True)):
        with pytest.raises(ValueError, match="need the simulator"):
            describe_graph(options)


def test_names_resolve_with_or_without_yaml_and_unknown_ones_list_the_valid():
    assert SCENARIOS.resolve("ground_start") == SCENARIOS.resolve("ground_start.yaml")
    assert JOY_SCRIPTS.resolve("integration_flight").endswith("integration_flight.yaml")
    with pytest.raises(UnknownNameError, match="unknown scenario 'nowhere'; valid: .*ground_start"):
        SCENARIOS.resolve("nowhere")
    with pytest.raises(ValueError, match="has n = 3, the graph n = 4"):
        describe_graph(GraphOptions(n=4))


def test_every_executable_has_a_node_class_whose_module_is_its_console_script():
    scripts = {}
    for dist in ("fpr_sim", "fpr_px4_bridge", "fpr_estimation", "fpr_control", "fpr_experiments"):
        for entry in importlib.metadata.distribution(dist).entry_points:
            if entry.group == "console_scripts":
                scripts[entry.name] = (dist, entry.value)
    assert set(NODE_CLASSES) == set(EXECUTABLES)
    for executable, target in NODE_CLASSES.items():
        package, _ = EXECUTABLES[executable]
        dist, script = scripts[executable]
        assert dist == package
        assert script == target.split(":")[0] + ":main", executable


def test_rcl_applies_files_overrides_and_only_the_matching_node_section(tmp_path):
    """Parameters reach the nodes through rcl's --params-file handling (per-node cli_args): a section for
    /fpr/uav2/controller applies to UAV 2's controller only (the old hand-written reader applied it to all)."""
    import rclpy
    from fpr_experiments.node_factory import build_nodes

    extra = tmp_path / "extra.yaml"
    extra.write_text("/fpr/uav2/controller:\n  ros__parameters:\n    info_timeout: 0.35\n")
    specs = [s for s in describe_graph(GraphOptions(params_files={"controller": [str(extra)]},
                                                    parameters={"controller": {"max_thrust": 21.5}}))
             if s.executable == "controller"]
    context = rclpy.Context()
    rclpy.init(context=context, args=[])
    try:
        nodes = build_nodes(specs, context)
        try:
            values = [(n.get_fully_qualified_name(), n.get_parameter("info_timeout").value,
                       n.get_parameter("max_thrust").value, n.get_parameter("uav_id").value,
                       n.get_parameter("use_sim_time").value) for n in nodes]
        finally:
            for n in nodes:
                n.destroy_node()
    finally:
        context.try_shutdown()
    assert values == [("/fpr/uav1/controller", 0.2, 21.5, 1, True), ("/fpr/uav2/controller", 0.35, 21.5, 2, True),
                      ("/fpr/uav3/controller", 0.2, 21.5, 3, True)]


def test_a_parameter_no_node_declares_stops_the_build_with_its_name():
    """rclpy ignores an override of an undeclared parameter: a misspelt --param or YAML key would fly unnoticed."""
    import rclpy
    from fpr_experiments.node_factory import build_nodes

    specs = [s for s in describe_graph(GraphOptions(parameters={"controller": {"max_thrst": 21.5}}))
             if s.executable == "controller"]
    context = rclpy.Context()
    rclpy.init(context=context, args=[])
    try:
        with pytest.raises(ValueError, match=r"/fpr/uav1/controller \(fpr_control controller\): no parameter named "
                                             r"max_thrst"):
            build_nodes(specs, context)
    finally:
        context.try_shutdown()
