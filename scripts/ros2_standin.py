#!/usr/bin/env python3
"""A tiny stand-in for the `ros2` command, installed by scripts/setup.sh only when no real `ros2` exists.

Supports what this project needs, with the same syntax as ros2cli:
  ros2 run <package> <executable> [args ...]     (e.g. --ros-args -p name:=value -r from:=to)
  ros2 pkg prefix <package>
  ros2 pkg executables [<package>]
Packages are found through AMENT_PREFIX_PATH (source install/setup.bash first), like ros2cli does.
"""
import os
import sys


def _prefixes() -> list[str]:
    return [p for p in os.environ.get('AMENT_PREFIX_PATH', '').split(os.pathsep) if p]


def _prefix_of(package: str) -> str | None:
    for prefix in _prefixes():
        if os.path.exists(os.path.join(prefix, 'share', 'ament_index', 'resource_index', 'packages', package)):
            return prefix
    return None


def _executables(prefix: str, package: str) -> list[str]:
    libdir = os.path.join(prefix, 'lib', package)
    if not os.path.isdir(libdir):
        return []
    return sorted(f for f in os.listdir(libdir)
                  if os.path.isfile(os.path.join(libdir, f)) and os.access(os.path.join(libdir, f), os.X_OK))


def _fail(message: str) -> int:
    print(message, file=sys.stderr)
    return 1


def main(argv: list[str]) -> int:
    usage = ('usage: ros2 run <package> <executable> [args] | ros2 pkg prefix <package>'
             ' | ros2 pkg executables [<package>]')
    if len(argv) >= 3 and argv[0] == 'run':
        package, executable = argv[1], argv[2]
        prefix = _prefix_of(package)
        if prefix is None:
            return _fail(f'Package \'{package}\' not found (is install/setup.bash sourced?)')
        path = os.path.join(prefix, 'lib', package, executable)
        if executable not in _executables(prefix, package):
            available = ', '.join(_executables(prefix, package))
            return _fail(f'No executable found: {package} {executable}; available: {available}')
        os.execv(path, [path, *argv[3:]])
    if len(argv) == 3 and argv[:2] == ['pkg', 'prefix']:
        prefix = _prefix_of(argv[2])
        if prefix is None:
            return _fail(f'Package not found: {argv[2]}')
        print(prefix)
        return 0
    if len(argv) in (2, 3) and argv[:2] == ['pkg', 'executables']:
        for prefix in _prefixes():
            index = os.path.join(prefix, 'share', 'ament_index', 'resource_index', 'packages')
            if len(argv) == 3:
                packages = [argv[2]]
            else:
                packages = sorted(os.listdir(index)) if os.path.isdir(index) else []
            for package in packages:
                for exe in _executables(prefix, package):
                    print(package, exe)
        return 0
    return _fail(usage)


if __name__ == '__main__':
    sys.exit(main(sys.argv[1:]))
