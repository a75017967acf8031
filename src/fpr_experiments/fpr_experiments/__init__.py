"""fpr_experiments: the FPR node graph description (one function, three consumers: the in-process runner, the
multi-process runner and ``launch/fpr.launch.py``) and the thesis's Chapter 3 and 4 experiments as a runnable
suite with reports. See README.md.

The cores (graph, catalog, metrics, thesis, report, plots, pilot, link) import no rclpy; the runners do.
"""

from __future__ import annotations

__all__ = ["run_experiment"]


def run_experiment(name: str, **options):
    """Run an experiment by name: see :func:`fpr_experiments.runner.run_experiment`."""
    from fpr_experiments.runner import run_experiment as _run

    return _run(name, **options)
