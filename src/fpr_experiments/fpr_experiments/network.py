"""Where the simulated graph's middleware traffic can go, and what the runners do about it (DESIGN.md §6).

Every run here goes through ``scripts/isolated.sh``: a private network namespace with loopback only
(``FPR_IN_NETNS=1``), ``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST``, a random ``ROS_DOMAIN_ID``. On a workstation
with a real Jazzy install a user may start ``ros2 run fpr_experiments run …`` directly; the runners then say in
one line what their DDS traffic can reach (:func:`isolation_line`) instead of refusing: a visualisation on another
computer is a legitimate use.
"""

from __future__ import annotations

import os

#: Fast DDS for the multi-process runner when it runs where nothing but loopback exists (scripts/isolated.sh's
#: network namespace): UDP only, no shared memory, as between the robot's computers
#: (:func:`separate_hosts_environment`)
SEPARATE_HOSTS_ENVIRONMENT = {"ROS_AUTOMATIC_DISCOVERY_RANGE": "SUBNET", "FASTDDS_BUILTIN_TRANSPORTS": "UDPv4"}


def network_interfaces(net_dev: str = "/proc/self/net/dev") -> set[str]:
    """The network interfaces of this process's network namespace (``/proc/self/net/dev`` is per namespace;
    ``/sys/class/net`` shows the namespace that mounted sysfs); empty when unreadable."""
    try:
        with open(net_dev, encoding="ascii") as dev:
            return {line.split(":", 1)[0].strip() for line in dev.read().splitlines()[2:] if ":" in line}
    except OSError:
        return set()


def separate_hosts_environment(net_dev: str = "/proc/self/net/dev") -> dict[str, str]:
    """The middleware settings of the multi-process runner (fpr_experiments.processes.run_processes):
    :data:`SEPARATE_HOSTS_ENVIRONMENT` when this runs in scripts/isolated.sh's network namespace
    (``FPR_IN_NETNS=1``) AND the namespace has no interface but loopback (so a subnet-wide discovery cannot leave
    the machine), else nothing (LOCALHOST stays).

    Why: the processes stand for separate computers, which talk UDP over Wi-Fi. Between processes of one host
    Fast DDS uses shared memory, and there a SIGSTOPped (frozen) subscriber process blocked a best-effort
    publish() for 1.0 s, once a second, in 1-2 of 8 trials (benchmarks/dds_hung_subscriber.py, fpr_px4_bridge
    README); on UDP only, 0 of 10. Under ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST, rmw_fastrtps sets the transports
    itself (FASTDDS_BUILTIN_TRANSPORTS has no effect), hence SUBNET, which loopback alone confines."""
    if os.environ.get("FPR_IN_NETNS") != "1" or network_interfaces(net_dev) != {"lo"}:
        return {}
    return dict(SEPARATE_HOSTS_ENVIRONMENT)


def isolation_line(net_dev: str = "/proc/self/net/dev") -> tuple[str, bool]:
    """One log line on where this process's DDS traffic can go, and whether it is a warning: inside a
    loopback-only namespace nothing leaves the machine; outside one, LOCALHOST discovery keeps the graph on this
    host; any other range (Jazzy's default is SUBNET) makes the simulated swarm's topics visible on the LAN, in
    domain ``ROS_DOMAIN_ID`` (0 unless set), and lets another computer's nodes of that domain into the run."""
    interfaces = network_interfaces(net_dev)
    if interfaces == {"lo"}:
        return "network: private namespace with loopback only: nothing leaves this machine", False
    discovery = os.environ.get("ROS_AUTOMATIC_DISCOVERY_RANGE", "") or "SUBNET (Jazzy's default)"
    domain = os.environ.get("ROS_DOMAIN_ID", "") or "0"
    if discovery.upper() in ("LOCALHOST", "OFF"):
        return (f"network: no private namespace; ROS discovery {discovery}, domain {domain}: the graph stays on "
                "this host (scripts/isolated.sh adds a loopback-only namespace)", False)
    return (f"WARNING network: no private namespace and ROS discovery {discovery}, domain {domain}: the simulated "
            "swarm's topics can be seen from, and mixed with, other computers of your LAN. Run through "
            "scripts/isolated.sh, or export ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST", True)


def say_isolation() -> None:
    """Print :func:`isolation_line` (a warning on stderr), once at a runner's start."""
    import sys

    line, warning = isolation_line()
    print(line, file=sys.stderr if warning else sys.stdout, flush=True)
