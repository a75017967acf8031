"""Where the packages' configuration files are, and name resolution for scenarios, joy scripts, models and
experiments (ROS-free: the ament index is used when present, else the source tree next to this package).

A name resolves with or without its ``.yaml``; an existing path is taken as is. An unknown name raises
:class:`UnknownNameError`, whose message lists the valid names (the CLI prints it as one line).
"""

from __future__ import annotations

import os
from dataclasses import dataclass

#: this source tree's src/ folder (used when a package is not in the ament index, e.g. plain pytest)
SOURCE_ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


class UnknownNameError(ValueError):
    """A scenario / script / experiment name that does not exist (the message lists the valid ones)."""


def share_directory(package: str) -> str:
    """``share/<package>`` of the installed package (ament index), else ``src/<package>`` of this tree."""
    try:
        from ament_index_python.packages import PackageNotFoundError, get_package_share_directory

        try:
            return get_package_share_directory(package)
        except PackageNotFoundError:
            pass
    except ImportError:  # no ament index at all (a bare Python environment)
        pass
    return os.path.join(SOURCE_ROOT, package)


def config_path(package: str, *parts: str) -> str:
    """``<share>/config/<parts>`` of ``package`` (installed), falling back to the source tree."""
    path = os.path.join(share_directory(package), "config", *parts)
    if os.path.exists(path):
        return path
    return os.path.join(SOURCE_ROOT, package, "config", *parts)


@dataclass(frozen=True)
class ConfigKind:
    """A kind of named configuration file: where to look, in order."""

    what: str                                   #: "scenario", "joy script", ...
    folders: tuple[tuple[str, str], ...]        #: (package, folder under config/)

    def names(self) -> list[str]:
        """Every valid name (without ``.yaml``), sorted, each once (the first folder wins)."""
        found: set[str] = set()
        for package, folder in self.folders:
            directory = config_path(package, folder)
            if os.path.isdir(directory):
                found.update(f[:-5] for f in os.listdir(directory) if f.endswith(".yaml"))
        return sorted(found)

    def resolve(self, name: str) -> str:
        """Absolute path of ``name`` (a path, or a name with or without ``.yaml``)."""
        if not name:
            raise UnknownNameError(f"empty {self.what} name; valid: {', '.join(self.names())}")
        if os.path.isfile(name):
            return os.path.abspath(name)
        base = os.path.basename(name)
        file_name = base if base.endswith(".yaml") else base + ".yaml"
        if os.sep not in name:
            for package, folder in self.folders:
                path = config_path(package, folder, file_name)
                if os.path.isfile(path):
                    return os.path.abspath(path)
        raise UnknownNameError(f"unknown {self.what} '{name}'; valid: {', '.join(self.names())}")


SCENARIOS = ConfigKind("scenario", (("fpr_experiments", "scenarios"), ("fpr_sim", "scenarios")))
JOY_SCRIPTS = ConfigKind("joy script", (("fpr_experiments", "joy_scripts"), ("fpr_control", "joy_scripts")))
MODELS = ConfigKind("model file", (("fpr_experiments", "models"), ("fpr_model", "")))
EXPERIMENTS = ConfigKind("experiment", (("fpr_experiments", "experiments"),))
MAPPINGS = ConfigKind("teleop mapping", (("fpr_experiments", "mappings"), ("fpr_control", "")))

#: file-valued node parameters an experiment may give by name: (executable, parameter) -> where to look
FILE_PARAMETERS: dict[tuple[str, str], ConfigKind] = {
    ("controller", "model_file"): MODELS,
    ("teleop", "mapping_file"): MAPPINGS,
    ("pilot", "mapping_file"): MAPPINGS,
}


def resolve_file_parameters(parameters: dict[str, dict]) -> dict[str, dict]:
    """A copy of per-executable ``parameters`` with the :data:`FILE_PARAMETERS` given by name made absolute."""
    out = {executable: dict(values) for executable, values in parameters.items()}
    for (executable, name), kind in FILE_PARAMETERS.items():
        value = out.get(executable, {}).get(name)
        if isinstance(value, str) and value:
            out[executable][name] = kind.resolve(value)
    return out
