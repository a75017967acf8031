"""The thesis's reference values and how ours compare (ROS-free).

Reference values are read from ``config/thesis/thesis_experiments.yaml`` (the project's extraction of every
result of the thesis's Chapters 3 and 4 with its line number) by (spec entry, table, row, column): nothing is
copied by hand into the experiments. For each metric of each variant the comparison gives ours, the thesis's,
their ratio (ours / thesis); for each metric compared across variants, the thesis's ranking of the variants
(lower is better: every compared metric is an error, except the ``higher_is_better`` ones), ours, and whether
ours reproduces it. All thesis values are single hardware flights with a human in the loop: loose references,
not pass/fail thresholds (spec/thesis_experiments.md §5).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from typing import Any

from fpr_experiments.catalog import Experiment
from fpr_experiments.resources import config_path

#: metrics where a larger value is better (rankings are reversed)
HIGHER_IS_BETTER = ("success_rate", "detection_rate_pct")


@functools.cache
def spec() -> dict[str, Any]:
    import yaml

    with open(config_path("fpr_experiments", "thesis", "thesis_experiments.yaml"), encoding="utf-8") as stream:
        return yaml.safe_load(stream)


def spec_entry(entry_id: str) -> dict[str, Any]:
    for entry in spec()["experiments"]:
        if entry["id"] == entry_id:
            return entry
    raise KeyError(f"no thesis entry '{entry_id}' in thesis_experiments.yaml")


@dataclass(frozen=True)
class Reference:
    value: float
    unit: str
    table: str
    row: str
    column: str
    line: int
    printed: str


def _number(value: Any) -> float:
    """A table value as a number: success rates "5/7" as fractions, bounds "< 6" as their bound."""
    if isinstance(value, str):
        text = value.strip().lstrip("<>≤≥= ")
        if "/" in text:
            a, b = text.split("/")
            return float(a) / float(b)
        return float(text)
    return float(value)


def reference(entry_id: str, table: str, row: str, column: str) -> Reference:
    """The thesis value of (table, row, column) in spec entry ``entry_id``; KeyError if there is none."""
    for record in spec_entry(entry_id).get("results", []):
        if str(record.get("table")) == table and record.get("row") == row and record.get("column") == column:
            value = record.get("value")
            if value is None:
                raise KeyError(f"{entry_id}: {table}/{row}/{column} is printed '*' (no value)")
            try:
                number = _number(value)
            except (TypeError, ValueError):
                raise KeyError(f"{entry_id}: {table}/{row}/{column} is not a number ({value!r})") from None
            return Reference(number, str(record.get("unit", "")), table, row, column,
                             int(record.get("line", 0)), str(record.get("printed", value)))
    raise KeyError(f"{entry_id}: no thesis value for table {table}, row '{row}', column '{column}'")


@dataclass
class Comparison:
    metric: str
    ours: float
    thesis: Reference | None

    @property
    def ratio(self) -> float:
        if self.thesis is None or not math.isfinite(self.ours) or self.thesis.value == 0.0:
            return math.nan
        return self.ours / self.thesis.value


@dataclass
class Ordering:
    """The variants ranked on one metric, best first, by the thesis and by us (values kept for ties)."""

    metric: str
    thesis: dict[str, float]
    ours: dict[str, float]
    higher_is_better: bool = False

    def _ranked(self, values: dict[str, float]) -> list[str]:
        return sorted(values, key=lambda v: values[v], reverse=self.higher_is_better)

    def text(self, values: dict[str, float], labels: dict[str, str] | None = None) -> str:
        """"a < b = c" (best first; "=" joins thesis ties)."""
        labels = labels or {}
        ranked = self._ranked(values)
        out = labels.get(ranked[0], ranked[0])
        for before, variant in zip(ranked, ranked[1:], strict=False):
            out += (" = " if values[variant] == values[before] else (" > " if self.higher_is_better else " < ")) \
                + labels.get(variant, variant)
        return out

    @property
    def reproduced(self) -> bool:
        """Every strict thesis relation between two variants holds in ours (thesis ties are not judged)."""
        sign = -1.0 if self.higher_is_better else 1.0
        for a in self.thesis:
            for b in self.thesis:
                if sign * (self.thesis[a] - self.thesis[b]) < 0.0 and not sign * (self.ours[a] - self.ours[b]) < 0.0:
                    return False
        return True


def compare(experiment: Experiment, results: dict[str, dict[str, float]]) -> tuple[
        dict[str, list[Comparison]], list[Ordering]]:
    """Per variant the comparisons of every reported metric, and the orderings (see the module doc).
    ``results`` = {variant id: {metric: value}}."""
    comparisons: dict[str, list[Comparison]] = {}
    for variant in experiment.variants:
        if variant.id not in results:
            continue
        entry = experiment.resolved(variant)["spec_entry"]
        rows = []
        for column in experiment.metrics:
            ours = float(results[variant.id].get(column.metric, math.nan))
            ref = None
            row = column.row or variant.thesis_row
            name = column.column.replace("{variant}", variant.thesis_column)
            if column.table and row and "{variant}" not in name:
                try:
                    ref = reference(column.spec_entry or entry, column.table, row, name)
                except KeyError:
                    ref = None
            rows.append(Comparison(column.metric, ours, ref))
        comparisons[variant.id] = rows
    orderings = []
    if len(comparisons) >= 2:
        for k, column in enumerate(experiment.metrics):
            thesis_values, our_values = {}, {}
            for variant_id, rows in comparisons.items():
                c = rows[k]
                if c.thesis is not None:
                    thesis_values[variant_id] = c.thesis.value
                if math.isfinite(c.ours):
                    our_values[variant_id] = c.ours
            common = [v for v in thesis_values if v in our_values]
            if len(common) < 2 or len(set(thesis_values[v] for v in common)) < 2:
                continue  # nothing to rank (one value, or the thesis ties them all)
            orderings.append(Ordering(column.metric, {v: thesis_values[v] for v in common},
                                      {v: our_values[v] for v in common},
                                      column.metric.split(".")[-1] in HIGHER_IS_BETTER))
    return comparisons, orderings
