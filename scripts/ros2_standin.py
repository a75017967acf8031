#!/usr/bin/env python3
"""A small stand-in for the `ros2` command, installed by scripts/setup.sh only when no real `ros2` exists (the
PyPI ROS wheels ship no ros2cli). Same syntax and output format as ros2cli for what it supports:

  ros2 run <package> <executable> [args ...]     (e.g. --ros-args -p name:=value -r from:=to)
  ros2 pkg prefix <package> | ros2 pkg executables [<package>]
  ros2 topic list [-t] | info <topic> [-v] | echo <topic> [<type>] [--once] [--no-arr] | hz <topic> [--window N]
  ros2 node list
  ros2 param list <node> | get <node> <name> | set <node> <name> <value>
  ros2 interface show <pkg/msg/Type>

Packages are found through AMENT_PREFIX_PATH (source install/setup.bash first), like ros2cli. The graph commands
are plain rclpy: a temporary node spins ``--spin-time`` seconds (default 1.0), then until the graph stops changing
(as ros2cli does with ``--no-daemon``, which spins a fixed time); run them under scripts/isolated.sh like every other
ROS command here. Message types without a .msg file in an ament prefix (the PyPI wheels install none) are shown
from their generated Python class (field types and names, no comments). ``topic hz`` measures wall time.
"""
import importlib
import os
import sys
import time


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


def _run(argv: list[str]) -> int:
    package, executable = argv[0], argv[1]
    prefix = _prefix_of(package)
    if prefix is None:
        return _fail(f'Package \'{package}\' not found (is install/setup.bash sourced?)')
    path = os.path.join(prefix, 'lib', package, executable)
    if executable not in _executables(prefix, package):
        return _fail(f'No executable found: {package} {executable}; available: '
                     f'{", ".join(_executables(prefix, package))}')
    os.execv(path, [path, *argv[2:]])
    return 1  # not reached


def _pkg(argv: list[str]) -> int:
    if len(argv) == 2 and argv[0] == 'prefix':
        prefix = _prefix_of(argv[1])
        if prefix is None:
            return _fail(f'Package not found: {argv[1]}')
        print(prefix)
        return 0
    if len(argv) in (1, 2) and argv[0] == 'executables':
        for prefix in _prefixes():
            index = os.path.join(prefix, 'share', 'ament_index', 'resource_index', 'packages')
            packages = [argv[1]] if len(argv) == 2 else (sorted(os.listdir(index)) if os.path.isdir(index) else [])
            for package in packages:
                for exe in _executables(prefix, package):
                    print(package, exe)
        return 0
    return _fail('usage: ros2 pkg prefix <package> | ros2 pkg executables [<package>]')


# ------------------------------------------------------------------------------------------------ graph helpers
def _option(argv: list[str], name: str, default=None, flag: bool = False):
    """Remove ``name`` (and its value unless ``flag``) from argv; return the value (True for a present flag)."""
    if name not in argv:
        return default
    index = argv.index(name)
    if flag:
        del argv[index]
        return True
    if index + 1 >= len(argv):
        raise SystemExit(_fail(f'{name} needs a value'))
    value = argv[index + 1]
    del argv[index:index + 2]
    return value


class _Graph:
    """A temporary rclpy node that has spun long enough to discover the graph."""

    def __init__(self, spin_time: float) -> None:
        import rclpy
        from rclpy.executors import SingleThreadedExecutor

        self.rclpy = rclpy
        from rclpy.signals import SignalHandlerOptions

        # Ctrl-C and SIGTERM must reach the streaming loops as KeyboardInterrupt (_interrupt_on_signals). With
        # rclpy's own SIGINT handler the signal could shut the context down first, and spin_once raised
        # ExternalShutdownException (exit status 1: it failed CI's test_topic_hz_measures_the_rate once)
        rclpy.init(args=['--ros-args', '--disable-stdout-logs'], signal_handler_options=SignalHandlerOptions.NO)
        self.node = rclpy.create_node(f'_ros2cli_standin_{os.getpid()}', start_parameter_services=False)
        self.executor = SingleThreadedExecutor()
        self.executor.add_node(self.node)
        self.settle(spin_time)

    def settle(self, spin_time: float, quiet: float = 1.0, limit: float = 10.0) -> None:
        """Spin at least ``spin_time`` s, then until the graph has not changed for ``quiet`` s and every node found
        has its endpoints known (each rclpy node publishes /rosout: a node without a known publisher is only half
        discovered — Fast DDS gives a new participant the node names within ~0.5 s here, their endpoints after
        2-3 s), at most ``limit`` s."""
        self.spin(spin_time)
        start, last_change, snapshot = time.monotonic(), time.monotonic(), self._snapshot()
        while time.monotonic() - start < limit and (time.monotonic() - last_change < quiet
                                                     or not self._endpoints_known()
                                                     or (not self._foreign_nodes() and time.monotonic() - start < 4.0)):
            self.spin(0.25)
            current = self._snapshot()
            if current != snapshot:
                snapshot, last_change = current, time.monotonic()

    def _foreign_nodes(self) -> list:
        """The nodes found other than this one (now and then Fast DDS misses a new participant's first round of
        announcements here: with nothing found, wait up to 4 s for the next round before saying the graph is empty)."""
        return [n for n in self.node.get_node_names_and_namespaces() if n[0] != self.node.get_name()]

    def _endpoints_known(self) -> bool:
        own = self.node.get_name()
        for name, namespace in self.node.get_node_names_and_namespaces():
            if name == own:
                continue
            try:
                if not self.node.get_publisher_names_and_types_by_node(name, namespace):
                    return False
            except Exception:  # noqa: BLE001 - a node that vanished meanwhile
                continue
        return True

    def _snapshot(self) -> tuple:
        topics = sorted((name, tuple(types)) for name, types in self.node.get_topic_names_and_types())
        counts = tuple(self.node.count_publishers(name) + 1000 * self.node.count_subscribers(name)
                       for name, _ in topics)
        return tuple(topics), counts, tuple(sorted(self.node.get_node_names_and_namespaces()))

    def spin(self, seconds: float) -> None:
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            self.executor.spin_once(timeout_sec=min(0.05, max(0.0, end - time.monotonic())))

    def close(self) -> None:
        self.node.destroy_node()
        self.rclpy.try_shutdown()

    def topic_types(self) -> dict[str, list[str]]:
        return dict(self.node.get_topic_names_and_types())


def _message_class(type_name: str):
    parts = type_name.split('/')
    if len(parts) == 2:
        parts = [parts[0], 'msg', parts[1]]
    if len(parts) != 3:
        raise SystemExit(_fail(f'The passed message type \'{type_name}\' is invalid'))
    try:
        return getattr(importlib.import_module(f'{parts[0]}.{parts[1]}'), parts[2])
    except (ImportError, AttributeError):
        raise SystemExit(_fail(f'The message type \'{type_name}\' is invalid')) from None


def _to_plain(value, no_arr: bool = False):
    if hasattr(value, 'get_fields_and_field_types'):
        return {field: _to_plain(getattr(value, field), no_arr) for field in value.get_fields_and_field_types()}
    if hasattr(value, 'tolist'):
        value = value.tolist()
    if isinstance(value, (list, tuple)) or type(value).__name__ == 'array':
        if no_arr:
            return f'<sequence of {len(value)} values>'
        return [_to_plain(v, no_arr) for v in value]
    if isinstance(value, bytes):
        return list(value)
    return value


def _qos_for(graph: _Graph, topic: str):
    """Best effort when any publisher is best effort (so every publisher can connect), else reliable."""
    from rclpy.qos import QoSProfile, ReliabilityPolicy

    infos = graph.node.get_publishers_info_by_topic(topic)
    best_effort = any(i.qos_profile.reliability == ReliabilityPolicy.BEST_EFFORT for i in infos)
    return QoSProfile(depth=10, reliability=ReliabilityPolicy.BEST_EFFORT if best_effort
                      else ReliabilityPolicy.RELIABLE)


def _resolve_type(graph: _Graph, topic: str, given: str | None) -> str | None:
    if given:
        return given
    types = graph.topic_types().get(topic)
    return types[0] if types else None


# ------------------------------------------------------------------------------------------------ ros2 topic
def _topic(argv: list[str], spin_time: float) -> int:
    usage = 'usage: ros2 topic list [-t] | info <topic> [-v] | echo <topic> [<type>] [--once] | hz <topic>'
    if not argv:
        return _fail(usage)
    command, args = argv[0], argv[1:]
    show_types = _option(args, '-t', False, flag=True) or _option(args, '--show-types', False, flag=True)
    verbose = _option(args, '-v', False, flag=True) or _option(args, '--verbose', False, flag=True)
    once = _option(args, '--once', False, flag=True)
    no_arr = _option(args, '--no-arr', False, flag=True)
    window = int(_option(args, '--window', '10000'))
    graph = _Graph(spin_time)
    try:
        if command == 'list' and not args:
            for name, types in sorted(graph.topic_types().items()):
                print(f'{name} [{", ".join(types)}]' if show_types else name)
            return 0
        if command == 'info' and len(args) == 1:
            topic = args[0]
            types = graph.topic_types().get(topic)
            if not types:
                return _fail(f'Unknown topic \'{topic}\'')
            publishers = graph.node.get_publishers_info_by_topic(topic)
            subscriptions = graph.node.get_subscriptions_info_by_topic(topic)
            print(f'Type: {", ".join(types)}\n\nPublisher count: {len(publishers)}')
            for info in publishers if verbose else []:
                print(f'\nNode name: {info.node_name}\nNode namespace: {info.node_namespace}\n'
                      f'Endpoint type: PUBLISHER\nQoS profile:\n  Reliability: {info.qos_profile.reliability.name}\n'
                      f'  Durability: {info.qos_profile.durability.name}')
            print(f'\nSubscription count: {len(subscriptions)}')
            for info in subscriptions if verbose else []:
                print(f'\nNode name: {info.node_name}\nNode namespace: {info.node_namespace}\n'
                      f'Endpoint type: SUBSCRIPTION\nQoS profile:\n  Reliability: {info.qos_profile.reliability.name}')
            return 0
        if command in ('echo', 'hz') and 1 <= len(args) <= 2:
            topic = args[0]
            type_name = _resolve_type(graph, topic, args[1] if len(args) == 2 else None)
            if type_name is None:
                return _fail(f'Could not determine the type for the passed topic \'{topic}\' (give it as the '
                             'second argument)')
            message_class = _message_class(type_name)
            return _echo(graph, topic, message_class, once, no_arr) if command == 'echo' \
                else _hz(graph, topic, message_class, window)
        return _fail(usage)
    finally:
        graph.close()


def _echo(graph: _Graph, topic: str, message_class, once: bool, no_arr: bool) -> int:
    import yaml

    received = []

    def on_message(message) -> None:
        sys.stdout.write(yaml.safe_dump(_to_plain(message, no_arr), sort_keys=False, default_flow_style=False))
        sys.stdout.write('---\n')
        sys.stdout.flush()
        received.append(1)

    graph.node.create_subscription(message_class, topic, on_message, _qos_for(graph, topic))
    try:
        while not (once and received):
            graph.executor.spin_once(timeout_sec=0.1)
    except KeyboardInterrupt:
        pass
    return 0


def _hz(graph: _Graph, topic: str, message_class, window: int) -> int:
    stamps: list[float] = []

    def on_message(_message) -> None:
        stamps.append(time.monotonic())
        del stamps[:-window - 1]

    graph.node.create_subscription(message_class, topic, on_message, _qos_for(graph, topic))
    last_print = time.monotonic()
    try:
        while True:
            graph.executor.spin_once(timeout_sec=0.05)
            if time.monotonic() - last_print >= 1.0:
                last_print = time.monotonic()
                if len(stamps) < 2:
                    print('no new messages', flush=True)
                    continue
                periods = [b - a for a, b in zip(stamps, stamps[1:], strict=False)]
                mean = sum(periods) / len(periods)
                std = (sum((p - mean) ** 2 for p in periods) / len(periods)) ** 0.5
                print(f'average rate: {1.0 / mean:.3f}\n\tmin: {min(periods):.3f}s max: {max(periods):.3f}s '
                      f'std dev: {std:.5f}s window: {len(periods) + 1}', flush=True)
    except KeyboardInterrupt:
        return 0


# ------------------------------------------------------------------------------------------------ ros2 node
def _node(argv: list[str], spin_time: float) -> int:
    if argv != ['list']:
        return _fail('usage: ros2 node list')
    graph = _Graph(spin_time)
    try:
        own = graph.node.get_name()
        names = {(ns.rstrip('/') + '/' + name) for name, ns in graph.node.get_node_names_and_namespaces()
                 if name != own}
        for name in sorted(names):
            print(name)
        return 0
    finally:
        graph.close()


# ------------------------------------------------------------------------------------------------ ros2 param
def _parameter_from_string(name: str, text: str):
    """ros2param's rule: the value is read as YAML (true, 3, 2.5, [1, 2], 'text')."""
    import yaml
    from rclpy.parameter import Parameter

    try:
        value = yaml.safe_load(text)
    except yaml.YAMLError:
        value = text
    if value is None:
        value = text
    return Parameter(name, value=value)


def _print_value(value) -> None:
    from rcl_interfaces.msg import ParameterType

    kinds = {ParameterType.PARAMETER_BOOL: ('Boolean', value.bool_value),
             ParameterType.PARAMETER_INTEGER: ('Integer', value.integer_value),
             ParameterType.PARAMETER_DOUBLE: ('Double', value.double_value),
             ParameterType.PARAMETER_STRING: ('String', value.string_value),
             ParameterType.PARAMETER_BYTE_ARRAY: ('Byte values', list(value.byte_array_value)),
             ParameterType.PARAMETER_BOOL_ARRAY: ('Boolean values', list(value.bool_array_value)),
             ParameterType.PARAMETER_INTEGER_ARRAY: ('Integer values', list(value.integer_array_value)),
             ParameterType.PARAMETER_DOUBLE_ARRAY: ('Double values', list(value.double_array_value)),
             ParameterType.PARAMETER_STRING_ARRAY: ('String values', list(value.string_array_value))}
    if value.type not in kinds:
        print('Parameter not set.')
        return
    label, shown = kinds[value.type]
    print(f'{label} {"are" if "values" in label else "value is"}: {shown}')


def _param(argv: list[str], spin_time: float) -> int:
    usage = 'usage: ros2 param list <node> | get <node> <name> | set <node> <name> <value>'
    if len(argv) < 2 or (argv[0], len(argv)) not in (('list', 2), ('get', 3), ('set', 4)):
        return _fail(usage)
    from rclpy.parameter_client import AsyncParameterClient

    command, node_name = argv[0], argv[1] if argv[1].startswith('/') else '/' + argv[1]
    graph = _Graph(spin_time)
    try:
        client = AsyncParameterClient(graph.node, node_name)
        if not client.wait_for_services(timeout_sec=max(2.0, spin_time)):
            return _fail(f'Node not found: {node_name} (or it has no parameter services)')
        if command == 'list':
            future = client.list_parameters()
        elif command == 'get':
            future = client.get_parameters([argv[2]])
        else:
            future = client.set_parameters([_parameter_from_string(argv[2], argv[3])])
        graph.executor.spin_until_future_complete(future, timeout_sec=5.0)
        if not future.done() or future.result() is None:
            return _fail(f'{command}: no answer from {node_name}')
        result = future.result()
        if command == 'list':
            print(f'{node_name}:')
            for name in sorted(result.result.names):
                print(f'  {name}')
        elif command == 'get':
            _print_value(result.values[0])
        else:
            outcome = result.results[0]
            if outcome.successful:
                print('Set parameter successful')
            else:
                print(f'Setting parameter failed: {outcome.reason}')
                return 1
        return 0
    finally:
        graph.close()


# ------------------------------------------------------------------------------------------------ ros2 interface
def _interface(argv: list[str]) -> int:
    if len(argv) != 2 or argv[0] != 'show':
        return _fail('usage: ros2 interface show <pkg/msg/Type>')
    parts = argv[1].split('/')
    if len(parts) == 3:
        prefix = _prefix_of(parts[0])
        path = os.path.join(prefix, 'share', parts[0], parts[1], parts[2] + '.msg') if prefix else ''
        if path and os.path.exists(path):
            with open(path, encoding='utf-8') as stream:
                sys.stdout.write(stream.read())
            return 0
    message_class = _message_class(argv[1])
    print(f'# {argv[1]} (from the generated Python class: no .msg file installed; comments not available)')
    for name in dir(message_class):
        if name.isupper() and not name.startswith('_'):
            print(f'{type(getattr(message_class, name)).__name__} {name}={getattr(message_class, name)!r}')
    for field, field_type in message_class.get_fields_and_field_types().items():
        print(f'{field_type} {field}')
    return 0


def _interrupt_on_signals() -> None:
    """SIGINT (Ctrl-C) and SIGTERM end a streaming command (echo, hz) as KeyboardInterrupt: the node leaves the
    graph cleanly. Installed explicitly, whatever the inherited disposition: a process started from a
    non-interactive shell's background job inherits SIGINT ignored, and Python then installs no handler of its own
    (with rclpy's handler off, see _Graph, Ctrl-C would do nothing)."""
    import signal

    def interrupt(_signum, _frame):
        raise KeyboardInterrupt

    signal.signal(signal.SIGINT, interrupt)
    signal.signal(signal.SIGTERM, interrupt)


def main(argv: list[str]) -> int:
    _interrupt_on_signals()
    usage = ('usage: ros2 run <package> <executable> [args] | pkg prefix|executables | topic list|info|echo|hz | '
             'node list | param list|get|set | interface show')
    argv = list(argv)
    spin_time = float(_option(argv, '--spin-time', '1.0')) if argv[:1] in (['topic'], ['node'], ['param']) else 0.0
    if len(argv) >= 3 and argv[0] == 'run':
        return _run(argv[1:])
    if argv[:1] == ['pkg']:
        return _pkg(argv[1:])
    if argv[:1] == ['topic']:
        return _topic(argv[1:], spin_time)
    if argv[:1] == ['node']:
        return _node(argv[1:], spin_time)
    if argv[:1] == ['param']:
        return _param(argv[1:], spin_time)
    if argv[:1] == ['interface']:
        return _interface(argv[1:])
    return _fail(usage)


if __name__ == '__main__':
    sys.exit(main(sys.argv[1:]))
