"""launch/fpr.launch.py builds exactly the description's node list (the launch wheels are not installed here:
the launch / launch_ros API the file uses is stubbed, recording what the file asks for)."""

from __future__ import annotations

import importlib.util
import os
import sys
import types

import pytest
from fpr_experiments.graph import LAUNCH_ARGUMENTS, describe_graph, launch_options

LAUNCH_FILE = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "launch", "fpr.launch.py")


class _Recorded:
    def __init__(self, *args, **kwargs) -> None:
        self.args, self.kwargs = args, kwargs


class _Context:
    def __init__(self, configurations: dict[str, str]) -> None:
        self.launch_configurations = configurations


class _LaunchConfiguration:
    def __init__(self, name: str) -> None:
        self.name = name

    def perform(self, context: _Context) -> str:
        return context.launch_configurations[self.name]


@pytest.fixture()
def launch_module(monkeypatch):
    stubs = {
        "launch": types.SimpleNamespace(LaunchDescription=lambda actions: list(actions)),
        "launch.actions": types.SimpleNamespace(DeclareLaunchArgument=type("DeclareLaunchArgument", (_Recorded,), {}),
                                                OpaqueFunction=type("OpaqueFunction", (_Recorded,), {}),
                                                SetEnvironmentVariable=type("SetEnvironmentVariable", (_Recorded,),
                                                                            {})),
        "launch.substitutions": types.SimpleNamespace(LaunchConfiguration=_LaunchConfiguration),
        "launch_ros": types.SimpleNamespace(),
        "launch_ros.actions": types.SimpleNamespace(Node=type("Node", (_Recorded,), {})),
    }
    for name, module in stubs.items():
        monkeypatch.setitem(sys.modules, name, module)
    spec = importlib.util.spec_from_file_location("fpr_launch_under_test", LAUNCH_FILE)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _launch(module, **arguments: str):
    description = module.generate_launch_description()
    declared = {a.args[0]: a.kwargs["default_value"] for a in description
                if type(a).__name__ == "DeclareLaunchArgument"}
    configurations = {**declared, **arguments}
    opaque = next(a for a in description if type(a).__name__ == "OpaqueFunction")
    actions = opaque.kwargs["function"](_Context(configurations))
    return declared, actions


@pytest.mark.parametrize("arguments", [
    {},
    {"backend": "sim", "n": "3", "mode": "communicating"},
    {"backend": "sim", "mode": "impedance", "cameras": "images", "scenario": "hover", "script": "integration_hover"},
    {"backend": "real", "mode": "non_communicating"},
    {"backend": "real", "enclaves": "true"},
    {"backend": "sim", "realism": "hardware"},
    {"backend": "sim", "realism": "ideal", "scenario": "hover", "script": "integration_hover"},
])
def test_launch_file_builds_the_descriptions_node_list(launch_module, arguments):
    declared, actions = _launch(launch_module, **arguments)
    assert set(declared) == set(LAUNCH_ARGUMENTS)
    nodes = [a for a in actions if type(a).__name__ == "Node"]
    expected = describe_graph(launch_options({**{k: v[0] for k, v in LAUNCH_ARGUMENTS.items()}, **arguments}))
    assert len(nodes) == len(expected) > 0
    for node, spec in zip(nodes, expected, strict=True):
        kwargs = node.kwargs
        assert (kwargs["package"], kwargs["executable"], kwargs["name"]) == (spec.package, spec.executable, spec.name)
        assert (kwargs["namespace"] or "") == spec.namespace
        assert kwargs["parameters"] == [*spec.params_files, spec.parameters]
        assert kwargs["remappings"] == [tuple(r) for r in spec.remappings]
        expected_enclave = ["--enclave", spec.fully_qualified_name] if arguments.get("enclaves") == "true" else None
        assert kwargs["ros_arguments"] == expected_enclave
    if arguments.get("realism"):
        realism = [n.kwargs["parameters"][-1]["realism"] for n in nodes if n.kwargs["executable"] in (
            "simulator", "info_link")]
        assert realism == [arguments["realism"]] * (2 if arguments["realism"] == "hardware" else 1)
    environment = [a for a in actions if type(a).__name__ == "SetEnvironmentVariable"]
    if arguments.get("backend", "sim") == "sim":
        assert [a.args for a in environment] == [("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")]
        assert nodes[0].kwargs["executable"] == "simulator"
        assert all(n.kwargs["parameters"][-1]["use_sim_time"] is True for n in nodes[1:])
        assert "use_sim_time" not in nodes[0].kwargs["parameters"][-1]  # the simulator is the clock
    else:
        assert environment == []
        assert all(n.kwargs["executable"] != "simulator" for n in nodes)
        assert all("use_sim_time" not in n.kwargs["parameters"][-1] for n in nodes)


def test_a_bad_launch_argument_is_one_clear_error(launch_module):
    with pytest.raises(ValueError, match="mode 'bogus' is not one of"):
        _launch(launch_module, mode="bogus")
    with pytest.raises(ValueError, match="n must be an integer"):
        _launch(launch_module, n="three")
    with pytest.raises(ValueError, match="realism 'rough' is not one of ideal, hardware"):
        _launch(launch_module, realism="rough")
    with pytest.raises(ValueError, match="enclaves must be true or false"):
        _launch(launch_module, enclaves="maybe")
