"""fpr_experiments.faults' report: the simulator-kill table gives each bridge's delay from the kill and the silence
its watchdog measured (the test's two criteria, tests/test_fault_response.py)."""

from __future__ import annotations

from fpr_experiments.faults import FaultCase, FaultResult, format_table


def test_the_simulator_kill_table_shows_the_delay_and_the_silence_of_each_bridge():
    metrics = {"fault_time_s": 8.01, "link_lost_s": 1.53}
    for uav, (delay, silence) in enumerate([(0.51, 0.5), (1.53, 0.5), (0.54, 0.55)], start=1):
        metrics[f"link_lost_uav{uav}_s"] = delay
        metrics[f"link_lost_silence_uav{uav}_s"] = silence
    table = format_table([FaultResult(FaultCase(node="simulator", seed=3), metrics, [("killed simulator", 8.01, 0.0)],
                                      "/tmp", True)])
    header, rule, row = table.splitlines()
    assert header.count("(silence [s])") == 3 and rule.count("|") == 6
    assert row == "| 8.01 | 3 | 0.51 (0.50) | 1.53 (0.50) | 0.54 (0.55) |"
