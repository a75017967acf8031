"""benchmarks/bench_graph.py's summary lines: the mean RTF of repeated levers and issue 11's figure (the hardware
profile's cost against the default), computed from the runs it printed."""

from __future__ import annotations

import os
import sys

sys.path.insert(0, os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "benchmarks"))
import bench_graph  # noqa: E402


def test_hardware_cost_and_means_from_the_runs():
    ideal, hardware = bench_graph.IDEAL_LEVER, bench_graph.HARDWARE_LEVER
    assert ideal in bench_graph.LEVERS and hardware in bench_graph.LEVERS
    runs = [("n3_images", ideal, 2.0), ("n3_images", hardware, 1.5), ("n3_images", ideal, 1.8),
            ("n3_images", hardware, 1.5), ("n6_emulated", ideal, 1.3)]
    lines = bench_graph.summary(runs)
    assert "# mean RTF n3_images " + ideal + ": 1.90 over 2 runs (1.80-2.00)" in lines
    assert "# mean RTF n3_images " + hardware + ": 1.50 over 2 runs (1.50-1.50)" in lines
    cost = [line for line in lines if "hardware profile's cost" in line]
    # 1 - 1.5 / 1.9 = 21 %; the pairs: 1 - 1.5 / 2.0 = 25 %, 1 - 1.5 / 1.8 = 17 %
    assert cost == ["# hardware profile's cost (issue 11: at most 20 %) n3_images: 21 % (mean RTF 1.90 ideal over 2 "
                    "runs, 1.50 hardware over 2; pairs 17-25 %)"]
    assert not any("n6_emulated" in line for line in lines)  # one run, no hardware run: nothing to say
