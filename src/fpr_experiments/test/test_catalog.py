"""The experiments as data: every shipped experiment loads, its files exist, its thesis references resolve."""

from __future__ import annotations

import math

import pytest
from fpr_experiments.catalog import experiment_from_dict, experiment_names, load_all, load_experiment
from fpr_experiments.resources import UnknownNameError
from fpr_experiments.thesis import reference, spec_entry

#: the thesis experiments the suite must cover (issue: every Ch. 3 and Ch. 4 experiment)
REQUIRED = ("fig_3_4", "table_3_2", "table_3_3", "table_3_4", "table_3_6", "table_3_7", "table_4_2", "table_4_3",
            "table_4_6", "table_4_7", "comm_loss", "takeoff_landing", "n4_unequal", "n6_unequal")


def test_every_required_experiment_is_there_and_loads():
    names = experiment_names()
    assert set(REQUIRED) <= set(names)
    for experiment in load_all():
        assert experiment.id in names
        assert experiment.variants and experiment.metrics


def test_names_resolve_with_or_without_yaml():
    assert load_experiment("table_3_3").id == load_experiment("table_3_3.yaml").id == "table_3_3"
    with pytest.raises(UnknownNameError, match="unknown experiment 'table_9_9'; valid: .*table_3_2"):
        load_experiment("table_9_9")


def test_every_thesis_reference_resolves_to_a_number():
    """A typo in a row / column / entry name would silently drop the thesis value from the reports."""
    checked = 0
    for experiment in load_all():
        for variant in experiment.variants:
            entry = experiment.resolved(variant)["spec_entry"]
            for column in experiment.metrics:
                if not column.table:
                    continue
                row = column.row or variant.thesis_row
                name = column.column.replace("{variant}", variant.thesis_column)
                value = reference(column.spec_entry or entry, column.table, row, name).value
                assert math.isfinite(value), (experiment.id, variant.id, column.metric)
                checked += 1
    assert checked >= 150


def test_every_ch3_and_ch4_table_of_the_spec_is_covered():
    covered = set()
    for experiment in load_all():
        for variant in experiment.variants:
            entry = experiment.resolved(variant)["spec_entry"]
            covered.update((column.spec_entry or entry, column.table) for column in experiment.metrics
                           if column.table not in ("", "text"))
    for entry_id, table in (("table_3_2", "3.2"), ("table_3_3", "3.3"), ("table_3_4", "3.4"), ("table_3_6", "3.6"),
                            ("table_3_7_task_1_case_1", "3.7"), ("table_3_7_task_1_case_2", "3.7"),
                            ("table_3_7_task_2", "3.7"), ("table_3_7_task_3", "3.7"), ("table_4_2", "4.2"),
                            ("table_4_3", "4.3"), ("table_4_6_pickup", "4.6"), ("table_4_6_pickup", "4.7"),
                            ("table_4_6_pickup", "4.8"), ("table_4_7_contact", "4.7"), ("table_4_7_contact", "4.8")):
        assert spec_entry(entry_id)
        assert (entry_id, table) in covered, (entry_id, table)


BASE = {"id": "x", "title": "t", "scenario": "ground_start", "script": "integration_flight", "duration": 10.0,
        "variants": [{"id": "a"}], "metrics": [{"metric": "roll_rmse_deg"}]}


def test_a_scenario_never_travels_without_its_script():
    with pytest.raises(ValueError, match="travel together"):
        experiment_from_dict({**BASE, "variants": [{"id": "a", "scenario": "hover"}]})


def test_bad_experiment_data_is_refused_with_the_valid_keys():
    with pytest.raises(ValueError, match="unknown key.*'scenaro'.*valid keys"):
        experiment_from_dict({**BASE, "scenaro": "hover"})
    with pytest.raises(UnknownNameError, match="unknown scenario 'hoover'"):
        experiment_from_dict({**BASE, "scenario": "hoover"})
    with pytest.raises(ValueError, match="duplicate variant"):
        experiment_from_dict({**BASE, "variants": [{"id": "a"}, {"id": "a"}]})
    with pytest.raises(ValueError, match="check 'roll_rmse_deg'"):
        experiment_from_dict({**BASE, "checks": {"roll_rmse_deg": {"below": 3}}})


def test_every_variant_graph_builds_with_every_parameter_it_sets_declared(tmp_path):
    """Every node of every variant's graph is built (not flown) with the catalog's parameters: a parameter no node
    declares (a typo in an experiment's YAML) stops the build with its name (fpr_experiments.node_factory), where
    rclpy alone would ignore it and the flight would run without it."""
    import rclpy
    from fpr_experiments.graph import describe_graph
    from fpr_experiments.node_factory import build_nodes
    from fpr_experiments.runner import effective_scenario, graph_options
    from fpr_sim.scenario import load_scenario

    built = 0
    for experiment in load_all():
        for variant in experiment.variants:
            resolved = experiment.resolved(variant)
            path = effective_scenario(resolved["scenario"], None, str(tmp_path / f"{experiment.id}_{variant.id}.yaml"),
                                      experiment.realism, None)
            specs = describe_graph(graph_options(experiment, variant, path, experiment.cameras,
                                                 load_scenario(path).n, realism=experiment.realism))
            context = rclpy.Context()
            rclpy.init(context=context, args=[])
            try:
                for node in build_nodes(specs, context, lean=True):
                    # lean: no parameter or type-description services (nothing to poll in the drains)
                    assert not list(node.services), [service.srv_name for service in node.services]
                    node.destroy_node()
                    built += 1
            finally:
                context.try_shutdown()
    assert built > 300  # 31 variants, 13-22 nodes each


def test_full_nodes_keep_their_services_for_the_tools():
    """Built for the robot (not lean), a node answers ``ros2 param`` and type-description queries."""
    import rclpy
    from fpr_experiments.graph import describe_graph
    from fpr_experiments.node_factory import build_node
    from fpr_experiments.resources import SCENARIOS
    from fpr_experiments.runner import graph_options

    experiment = load_experiment("takeoff_landing")
    specs = describe_graph(graph_options(experiment, experiment.variants[0], SCENARIOS.resolve(experiment.scenario),
                                         "emulated", 3))
    spec = next(s for s in specs if s.executable == "teleop")
    context = rclpy.Context()
    rclpy.init(context=context, args=[])
    try:
        node = build_node(spec, context, lean=False)
        names = {service.srv_name.rsplit("/", 1)[-1] for service in node.services}
        node.destroy_node()
    finally:
        context.try_shutdown()
    assert {"get_type_description", "get_parameters", "set_parameters"} <= names
