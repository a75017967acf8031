"""The experiments as data (ROS-free): one YAML file per experiment in ``config/experiments/``.

An experiment names everything a run needs — its scenario and its operator script (always together: a variant
that changes one must give both), the operator kind, the cameras, the controller mode and parameters, the
duration (and the shortened ``--quick`` one), its variants (the rows of the thesis's table), the metrics it
reports with the thesis table / column each one is compared to, and the flight checks the quick test asserts.
Where the thesis is silent, ``choices`` says what we chose and why, next to the definition. Unknown keys are
refused with the list of valid ones, like the scenarios.

Keys (all optional but ``id``, ``title``, ``scenario``, ``script``, ``duration``, ``variants``)::

    id: table_3_2                     # = the file name; also the spec entry unless `spec_entry` is given
    title: ...
    chapter: 3
    thesis: "§3.5.1, Table 3.2, l.5089-5125"
    spec_entry: table_3_2             # entry of config/thesis/thesis_experiments.yaml holding the thesis values
    description: ...
    choices: [...]                    # what we chose where the thesis is silent (shown in the reports)
    scenario: ch3_hover               # fpr_experiments or fpr_sim config/scenarios (with or without .yaml)
    script: ch3_hover                 # fpr_experiments or fpr_control config/joy_scripts
    operator: joy_script              # joy_script | pilot
    cameras: emulated                 # emulated | images
    mode: impedance
    duration: 45.0                    # [s] simulated
    quick_duration: 15.0              # [s] with --quick (the test suite)
    quick_variants: [impedance]       # the variants the test suite flies quick ([] = all)
    parameters: {controller: {state_source: ground_truth}}   # per executable (fpr_experiments.graph)
    uav_parameters: [{executable: controller, uav_id: 2, parameters: {...}}]
    link_outage: [10.0, 13.0]         # [s] every zeta dropped in between (info_link node)
    detection_fallback: true          # the thesis's MOCAP supervision of lost / false detections (§4.4.2)
    realism: ideal                    # fpr_sim realism profile: ideal | hardware (default DEFAULT_REALISM)
    window: [11.0, 71.0]              # [s] metrics only inside (and inside the tracking window)
    variants:
      - {id: impedance, label: Impedance, thesis_row: Impedance, mode: impedance}
    metrics:                          # what the report tables show, each with its thesis reference
      - {metric: position_rmse_cm, table: "3.2", column: "RMSE p_p"}
    claims:                           # the thesis's claims, checked on each variant (lhs op rhs)
      - {text: "SOWO less noisy than FOWO", line: 5009, lhs: uav2.force_z_noise_n, op: "<", rhs: uav1.force_z_noise_n}
    checks: {max_abs_roll_deg: {max: 30}}   # quick-test assertions on metrics (own thresholds)
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Any

from fpr_experiments.resources import EXPERIMENTS, JOY_SCRIPTS, SCENARIOS, UnknownNameError

#: the realism profile of an experiment that names none (fpr_sim.scenario.realism_profiles): "hardware" (issue 11),
#: the simulator as hard to fly as the robot, calibrated on Table 3.2's impedance row and Table 4.2's C row only
#: (docs/calibration.md), every other experiment its validation (docs/results.md, docs/seed_spread.md). "ideal"
#: (the plant = the controllers' model, perfect sensors and link) stays for unit-level tests: the test suite's
#: graph-regression flights (tests/test_experiments_quick.py, tests/test_runners_agree.py) ask for it by name.
#: History: "ideal" was the default from stop 19 to stop 25 (the multi-process runner comparison failed with
#: hardware; it now pins ideal: it compares the runners, not the realism).
DEFAULT_REALISM = "hardware"

#: every experiment must keep these (DESIGN.md §5b): no flip, no fly-away, no crash, no NaN
DEFAULT_CHECKS: dict[str, dict[str, float]] = {
    "max_abs_roll_deg": {"max": 30.0},
    "max_abs_pitch_deg": {"max": 30.0},
    "max_height_m": {"max": 5.0},
    "max_excursion_m": {"max": 3.0},
    "nonfinite_samples": {"max": 0.0},
    "ground_contacts": {"max": 0.0},
    "swarm_emergencies": {"max": 0.0},  # the bridges' swarm guard landed or held the robot (metrics.json: why)
}


@dataclass
class MetricColumn:
    """A reported metric and the thesis value it is compared to (``row`` defaults to the variant's)."""

    metric: str
    table: str = ""              #: thesis table number ("3.2", "text" for a value in prose), "" = no reference
    column: str = ""             #: the spec's column name
    row: str = ""                #: the spec's row name ("" = the variant's thesis_row)
    spec_entry: str = ""         #: "" = the variant's / experiment's spec entry
    label: str = ""              #: short column title in the reports ("" = derived from the metric)


@dataclass
class Claim:
    """A thesis claim checked on each variant: ``lhs op rhs`` (metric names, or a number for ``rhs``)."""

    text: str
    lhs: str
    op: str
    rhs: str | float
    line: int = 0

    def evaluate(self, metrics: dict[str, float]) -> tuple[float, float, bool]:
        left = float(metrics.get(self.lhs, math.nan))
        right = float(self.rhs) if isinstance(self.rhs, int | float) else float(metrics.get(self.rhs, math.nan))
        if not (math.isfinite(left) and math.isfinite(right)):
            return left, right, False
        return left, right, {"<": left < right, ">": left > right, "<=": left <= right, ">=": left >= right}[self.op]


@dataclass
class UavParameters:
    executable: str
    uav_id: int
    parameters: dict[str, Any] = field(default_factory=dict)


@dataclass
class Variant:
    """One row of the experiment's table: a controller / gain set / task."""

    id: str
    label: str = ""
    thesis_row: str = ""          #: the thesis table's row of this variant (tables with one row per variant)
    thesis_column: str = ""       #: ... or its column (tables with one column per variant): fills "{variant}"
    spec_entry: str = ""          #: "" = the experiment's
    mode: str = ""                #: "" = the experiment's
    scenario: str = ""            #: given together with `script` (or neither)
    script: str = ""
    duration: float = 0.0         #: 0 = the experiment's
    quick_duration: float = 0.0
    parameters: dict[str, dict[str, Any]] = field(default_factory=dict)  #: merged over the experiment's
    uav_parameters: list[UavParameters] = field(default_factory=list)


@dataclass
class Experiment:
    id: str
    title: str
    scenario: str
    script: str
    duration: float
    variants: list[Variant]
    chapter: int = 0
    thesis: str = ""
    spec_entry: str = ""
    description: str = ""
    choices: list[str] = field(default_factory=list)
    operator: str = "joy_script"
    cameras: str = "emulated"
    mode: str = "communicating"
    quick_duration: float = 15.0
    #: variants the test suite flies with ``--quick`` ([] = all); ``run <name> --quick`` still flies all of them
    quick_variants: list[str] = field(default_factory=list)
    parameters: dict[str, dict[str, Any]] = field(default_factory=dict)
    uav_parameters: list[UavParameters] = field(default_factory=list)
    link_outage: list[float] = field(default_factory=list)
    #: the thesis's motion-capture supervision of the detections (§4.4.2; fpr_experiments.detection_fallback)
    detection_fallback: bool = False
    realism: str = DEFAULT_REALISM  #: fpr_sim realism profile of the simulator and the inter-UAV link
    #: [s] simulated: the metrics' window is the tracking window inside [start, end] ([] = the whole flight)
    window: list[float] = field(default_factory=list)
    metrics: list[MetricColumn] = field(default_factory=list)
    claims: list[Claim] = field(default_factory=list)
    checks: dict[str, dict[str, float]] = field(default_factory=dict)
    plots: list[str] = field(default_factory=list)  #: extra plot kinds (fpr_experiments.plots)

    # ---- derived -----------------------------------------------------------------------------------
    def variant(self, variant_id: str) -> Variant:
        for v in self.variants:
            if v.id == variant_id:
                return v
        raise UnknownNameError(f"experiment '{self.id}' has no variant '{variant_id}'; valid: "
                               f"{', '.join(v.id for v in self.variants)}")

    def resolved(self, variant: Variant) -> dict[str, Any]:
        """Scenario, script, mode, durations and merged parameters of one variant."""
        parameters = {k: dict(v) for k, v in self.parameters.items()}
        for executable, values in variant.parameters.items():
            parameters.setdefault(executable, {}).update(values)
        uav_parameters: dict[tuple[str, int], dict[str, Any]] = {}
        for entry in [*self.uav_parameters, *variant.uav_parameters]:
            uav_parameters.setdefault((entry.executable, entry.uav_id), {}).update(entry.parameters)
        return {"scenario": variant.scenario or self.scenario, "script": variant.script or self.script,
                "mode": variant.mode or self.mode, "duration": variant.duration or self.duration,
                "quick_duration": variant.quick_duration or self.quick_duration, "parameters": parameters,
                "uav_parameters": uav_parameters,
                "spec_entry": variant.spec_entry or self.spec_entry or self.id}

    def all_checks(self) -> dict[str, dict[str, float]]:
        checks = {k: dict(v) for k, v in DEFAULT_CHECKS.items()}
        for metric, bounds in self.checks.items():
            checks[metric] = dict(bounds)
        return checks


# ------------------------------------------------------------------------------------------------ loading
def check_keys(cls: type, data: Any, path: str) -> dict:
    """``data`` as a dict of ``cls``'s fields; a non-mapping or an unknown key is a ValueError naming the valid
    keys (shared by the experiment and the pilot-script loaders)."""
    if not isinstance(data, dict):
        raise ValueError(f"{path}: expected a mapping, got {data!r}")
    names = [f.name for f in dataclasses.fields(cls)]
    unknown = sorted(set(data) - set(names))
    if unknown:
        raise ValueError(f"{path}: unknown key(s) {unknown}; valid keys are {names}")
    return dict(data)


def _from_dict(cls: type, data: Any, path: str) -> Any:
    values = check_keys(cls, data, path)
    if cls is Experiment or cls is Variant:
        values["uav_parameters"] = [_from_dict(UavParameters, u, f"{path}.uav_parameters[{k}]")
                                    for k, u in enumerate(values.get("uav_parameters", []) or [])]
    if cls is Experiment:
        values["variants"] = [_from_dict(Variant, v, f"{path}.variants[{k}]")
                              for k, v in enumerate(values.get("variants", []) or [])]
        values["metrics"] = [_from_dict(MetricColumn, m, f"{path}.metrics[{k}]")
                             for k, m in enumerate(values.get("metrics", []) or [])]
        values["claims"] = [_from_dict(Claim, c, f"{path}.claims[{k}]")
                            for k, c in enumerate(values.get("claims", []) or [])]
    try:
        return cls(**values)
    except TypeError as error:
        raise ValueError(f"{path}: {error}") from None


def experiment_from_dict(data: dict, source: str = "experiment") -> Experiment:
    """Build and validate an :class:`Experiment` (names of scenarios and scripts must exist)."""
    experiment = _from_dict(Experiment, data, source)
    where = f"{source} ({experiment.id})"
    if not experiment.variants:
        raise ValueError(f"{where}: no variants")
    ids = [v.id for v in experiment.variants]
    if len(set(ids)) != len(ids):
        raise ValueError(f"{where}: duplicate variant ids {ids}")
    check_realism(experiment.realism, where)
    if experiment.operator not in ("joy_script", "pilot"):
        raise ValueError(f"{where}: operator must be joy_script or pilot, got '{experiment.operator}'")
    if experiment.cameras not in ("emulated", "images"):
        raise ValueError(f"{where}: cameras must be emulated or images, got '{experiment.cameras}'")
    for variant in experiment.variants:
        if bool(variant.scenario) != bool(variant.script):
            raise ValueError(f"{where}: variant '{variant.id}' gives a scenario or a script alone: a scenario "
                             "and its operator script always travel together")
        resolved = experiment.resolved(variant)
        SCENARIOS.resolve(resolved["scenario"])
        JOY_SCRIPTS.resolve(resolved["script"])
        if not (resolved["duration"] > 0.0 and resolved["quick_duration"] > 0.0) or not math.isfinite(
                resolved["duration"]):
            raise ValueError(f"{where}: variant '{variant.id}' needs positive durations")
    unknown_quick = sorted(set(experiment.quick_variants) - set(ids))
    if unknown_quick:
        raise ValueError(f"{where}: quick_variants {unknown_quick} are not variants ({', '.join(ids)})")
    if experiment.window and (len(experiment.window) != 2 or not experiment.window[0] < experiment.window[1]):
        raise ValueError(f"{where}: window must be [start, end] with start < end")
    if experiment.link_outage and (len(experiment.link_outage) != 2
                                   or not 0.0 <= experiment.link_outage[0] < experiment.link_outage[1]):
        raise ValueError(f"{where}: link_outage must be [start, end] with 0 <= start < end")
    for claim in experiment.claims:
        if claim.op not in ("<", ">", "<=", ">="):
            raise ValueError(f"{where}: claim '{claim.text}': op must be <, >, <= or >=, got '{claim.op}'")
    for metric, bounds in experiment.checks.items():
        if not isinstance(bounds, dict) or not set(bounds) <= {"min", "max"} or not bounds:
            raise ValueError(f"{where}: check '{metric}' must be {{min: x}} and/or {{max: y}}, got {bounds!r}")
    return experiment


def check_realism(profile: str, where: str = "realism") -> str:
    """``profile`` if it is one of fpr_sim's realism profiles, else a one-line ValueError listing them."""
    from fpr_sim.scenario import realism_profiles

    profiles = realism_profiles()
    if profile not in profiles:
        raise ValueError(f"{where}: unknown realism profile {profile!r}; profiles: {', '.join(profiles)}")
    return profile


def load_experiment(name: str) -> Experiment:
    """An experiment by name (with or without ``.yaml``) or path; unknown names list the valid ones."""
    import yaml

    path = EXPERIMENTS.resolve(name)
    with open(path, encoding="utf-8") as stream:
        data = yaml.safe_load(stream) or {}
    return experiment_from_dict(data, path)


def experiment_names() -> list[str]:
    return EXPERIMENTS.names()


def load_all() -> list[Experiment]:
    return [load_experiment(name) for name in experiment_names()]
