"""Package manifests that rosdep can install: every import declared, every key resolvable, one license.

Each package's Python imports (module-level and local, found with ``ast``; the standard library excluded) must be
declared in its package.xml (exec_depend, or test_depend for its tests), and every declared key must be either a
workspace package, a ROS package of the Jazzy distribution or a rosdistro python key (both in the pinned copy
``rosdep/upstream_keys.yaml``, checked by hand against ros/rosdistro), or a key of the repository's own rosdep
source ``rosdep/fpr.yaml`` (pip keys for what rosdistro lacks). The license is Apache-2.0 everywhere (LICENSE,
package.xml, setup.py).
"""

from __future__ import annotations

import ast
import re
import sys
import xml.etree.ElementTree as ElementTree
from pathlib import Path

import pytest
import yaml

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = sorted(p.parent for p in (ROOT / "src").glob("*/package.xml"))
WORKSPACE = {p.name for p in PACKAGES}

with open(ROOT / "rosdep" / "upstream_keys.yaml", encoding="utf-8") as _stream:
    _UPSTREAM = yaml.safe_load(_stream)
#: ROS 2 Jazzy packages (the pinned copy rosdep/upstream_keys.yaml, from rosdistro's jazzy/distribution.yaml)
ROS_PACKAGES = set(_UPSTREAM["ros_packages"])
#: keys present in ros/rosdistro rosdep/python.yaml (the pinned copy rosdep/upstream_keys.yaml)
UPSTREAM_KEYS = set(_UPSTREAM["python_keys"])
#: import name -> rosdep key
IMPORT_KEYS = {"numpy": "python3-numpy", "yaml": "python3-yaml", "cv2": "python3-opencv", "scipy": "python3-scipy",
               "matplotlib": "python3-matplotlib", "pymavlink": "python3-pymavlink-pip", "mcap": "python3-mcap-pip",
               "pytest": "python3-pytest", "foxglove": "python3-foxglove-sdk-pip",
               "websockets": "python3-websockets-pip"}


def _own_keys() -> set[str]:
    with open(ROOT / "rosdep" / "fpr.yaml", encoding="utf-8") as stream:
        return set(yaml.safe_load(stream))


def _dependencies(package: Path) -> dict[str, set[str]]:
    root = ElementTree.parse(package / "package.xml").getroot()
    out: dict[str, set[str]] = {"exec": set(), "test": set()}
    for element in root:
        if element.tag in ("depend", "exec_depend", "buildtool_depend", "build_depend"):
            out["exec"].add(element.text.strip())
        elif element.tag == "test_depend":
            out["test"].add(element.text.strip())
    return out


def _imports(paths: list[Path]) -> set[str]:
    names: set[str] = set()
    for path in paths:
        tree = ast.parse(path.read_text(encoding="utf-8"))
        for node in ast.walk(tree):
            if isinstance(node, ast.Import):
                names.update(alias.name.split(".")[0] for alias in node.names)
            elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
                names.add(node.module.split(".")[0])
    return {n for n in names if n not in sys.stdlib_module_names and n != "__future__"}


def _key(import_name: str) -> str | None:
    if import_name in IMPORT_KEYS:
        return IMPORT_KEYS[import_name]
    if import_name in WORKSPACE or import_name in ROS_PACKAGES:
        return import_name
    return None


def _sources(package: Path, tests: bool) -> list[Path]:
    if tests:
        return sorted((package / "test").glob("*.py")) if (package / "test").is_dir() else []
    files = sorted((package / package.name).rglob("*.py")) + sorted((package / "launch").glob("*.py"))
    return [f for f in files if "_kernels" not in f.parts or f.suffix == ".py"]


@pytest.mark.parametrize("package", PACKAGES, ids=lambda p: p.name)
def test_every_import_is_declared(package):
    deps = _dependencies(package)
    own_modules = {f.stem for f in (package / "test").glob("*.py")} if (package / "test").is_dir() else set()
    for tests in (False, True):
        declared = deps["exec"] | (deps["test"] if tests else set())
        missing = []
        for name in sorted(_imports(_sources(package, tests)) - own_modules - {package.name}):
            key = _key(name)
            if key is None:
                missing.append(f"{name} (no rosdep key known: add it to IMPORT_KEYS with its key)")
            elif key not in declared:
                missing.append(f"{name} -> <{'test' if tests else 'exec'}_depend>{key}</...>")
        assert not missing, f"{package.name}: undeclared {'test ' if tests else ''}imports: {missing}"


@pytest.mark.parametrize("package", PACKAGES, ids=lambda p: p.name)
def test_every_key_resolves(package):
    valid = WORKSPACE | ROS_PACKAGES | UPSTREAM_KEYS | _own_keys()
    deps = _dependencies(package)
    unknown = sorted((deps["exec"] | deps["test"]) - valid)
    assert not unknown, f"{package.name}: keys rosdep cannot resolve: {unknown}"


def test_own_rosdep_keys_are_pip_keys_that_rosdistro_lacks():
    keys = _own_keys()
    assert keys == {"python3-pymavlink-pip", "python3-mcap-pip", "python3-foxglove-sdk-pip", "python3-websockets-pip"}
    for key in keys:
        assert key.endswith("-pip") and key not in UPSTREAM_KEYS


def test_one_license():
    assert "Apache License" in (ROOT / "LICENSE").read_text(encoding="utf-8")[:200]
    for package in PACKAGES:
        licenses = [e.text for e in ElementTree.parse(package / "package.xml").getroot().iter("license")]
        assert licenses == ["Apache-2.0"], f"{package.name}: {licenses}"
        setup = package / "setup.py"
        if setup.exists():
            assert re.search(r"license\s*=\s*'Apache-2.0'", setup.read_text(encoding="utf-8")), setup
