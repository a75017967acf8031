"""The shipped Foxglove layout and RViz config (issue 14) match the graph: every panel of the layout tree is
configured, every plotted message path is a field of the message its topic carries, every frame they name is a
frame of the published robot (URDF) or of the TF tree, and the RViz config reads the robot model where the
simulator publishes it (latched /robot_description)."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest
import yaml

VIZ = Path(__file__).resolve().parents[1] / "src" / "fpr_experiments" / "config" / "viz"


def _message_types():
    from fpr_msgs.msg import ControllerStatus, FprState, LocalState, TeleopCommand

    return {r"/fpr/teleop": TeleopCommand, r"/fpr/ground_truth": FprState,
            r"/fpr/uav\d+/local_state": LocalState, r"/fpr/uav\d+/controller_status": ControllerStatus}


def _leaves(node):
    if isinstance(node, str):
        yield node
    else:
        yield from _leaves(node["first"])
        yield from _leaves(node["second"])


def _field_type(message_class, path: list[str]):
    """Walk a Foxglove message path (``a.b[0].c``) through the ROS message class; returns the leaf's type name."""
    instance = message_class()
    kind = None
    for part in path:
        name, index = re.fullmatch(r"([a-z_0-9]+)(\[\d+\])?", part).groups()
        fields = instance.get_fields_and_field_types()
        assert name in fields, f"{message_class.__name__} has no field {name!r} (fields: {sorted(fields)})"
        kind = fields[name]
        value = getattr(instance, name)
        if index is not None:
            assert kind.startswith("sequence<") or kind.endswith("]"), f"{name} is not an array"
            kind = kind.removeprefix("sequence<").rstrip(">")
            continue
        instance = value
    return kind


def _robot_frames() -> set[str]:
    from fpr_model.parameters import default_parameters
    from fpr_model.robot_description import robot_description
    from urdf_parser_py.urdf import URDF

    return {link.name for link in URDF.from_xml_string(robot_description(default_parameters(3))).links} | {"world"}


def test_foxglove_layout_panels_paths_and_frames():
    layout = json.loads((VIZ / "fpr_foxglove_layout.json").read_text())
    panels = layout["configById"]
    leaves = set(_leaves(layout["layout"]))
    assert leaves == set(panels), "every panel of the tree is configured and every configured panel is shown"
    types = _message_types()
    plotted = 0
    for panel_id, config in panels.items():
        if panel_id.startswith("Plot!"):
            for entry in config["paths"]:
                topic, *path = entry["value"].split(".")
                (message_class,) = [c for pattern, c in types.items() if re.fullmatch(pattern, topic)]
                kind = _field_type(message_class, path)
                assert kind in ("double", "float", "boolean", "uint8", "int32", "uint32"), (entry, kind)
                plotted += 1
        if panel_id.startswith("3D!"):
            assert config["followTf"] in _robot_frames()
            assert config["layers"]["grid"]["frameId"] == "world"
            assert {"/robot_description", "/tf", "/tf_static"} <= set(config["topics"])
        if panel_id.startswith("DiagnosticSummary!"):
            assert config["topicToRender"] == "/diagnostics"
    assert plotted >= 12


def test_rviz_config_reads_the_robot_model_and_names_real_frames():
    rviz = yaml.safe_load((VIZ / "fpr.rviz").read_text())
    manager = rviz["Visualization Manager"]
    assert manager["Global Options"]["Fixed Frame"] == "world"
    displays = {d["Class"]: d for d in manager["Displays"]}
    model = displays["rviz_default_plugins/RobotModel"]
    assert model["Description Source"] == "Topic" and model["Description Topic"]["Value"] == "/robot_description"
    # the simulator publishes the description latched (transient local): RViz must subscribe likewise to get it
    assert model["Description Topic"]["Durability Policy"] == "Transient Local"
    assert "rviz_default_plugins/TF" in displays
    assert manager["Views"]["Current"]["Target Frame"] in _robot_frames()


@pytest.mark.parametrize("name", ["fpr_foxglove_layout.json", "fpr.rviz"])
def test_viz_configs_are_installed(name):
    setup = (VIZ.parents[1] / "setup.py").read_text()
    assert "config/viz" in setup and (VIZ / name).exists()
