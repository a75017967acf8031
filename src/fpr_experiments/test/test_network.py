"""The multi-process runner's middleware choice (fpr_experiments.network.separate_hosts_environment): UDP only
when it runs in scripts/isolated.sh's network namespace with nothing but loopback, Fast DDS's defaults (LOCALHOST
discovery) anywhere else; and scripts/isolated.sh's own check that an inherited FPR_IN_NETNS=1 really is such a
namespace."""

from __future__ import annotations

import os
import shutil
import subprocess

import pytest
from fpr_experiments.network import (
    SEPARATE_HOSTS_ENVIRONMENT,
    isolation_line,
    network_interfaces,
    separate_hosts_environment,
)

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))))
HEADER = ("Inter-|   Receive                                                |  Transmit\n"
          " face |bytes    packets errs drop fifo frame compressed multicast|bytes    packets errs drop fifo colls "
          "carrier compressed\n")


def _net_dev(tmp_path, *names: str) -> str:
    path = tmp_path / "dev"
    path.write_text(HEADER + "".join(f"{name:>6}: 0 0 0 0 0 0 0 0 0 0 0 0 0 0 0 0\n" for name in names))
    return str(path)


def test_interfaces_are_read_from_the_namespace_s_net_dev(tmp_path):
    assert network_interfaces(_net_dev(tmp_path, "lo", "eth0")) == {"lo", "eth0"}
    assert network_interfaces(str(tmp_path / "missing")) == set()


@pytest.mark.parametrize(("in_netns", "interfaces", "udp_only"), [
    ("1", ("lo",), True),
    ("1", ("lo", "eth0"), False),  # FPR_IN_NETNS inherited, but a LAN is reachable: a subnet discovery would leave
    ("0", ("lo",), False),
    (None, ("lo",), False),
    ("1", (), False),  # unreadable or empty: not known to be confined
])
def test_udp_only_exactly_in_a_loopback_only_namespace(tmp_path, monkeypatch, in_netns, interfaces, udp_only):
    if in_netns is None:
        monkeypatch.delenv("FPR_IN_NETNS", raising=False)
    else:
        monkeypatch.setenv("FPR_IN_NETNS", in_netns)
    environment = separate_hosts_environment(_net_dev(tmp_path, *interfaces))
    assert environment == (SEPARATE_HOSTS_ENVIRONMENT if udp_only else {})
    if udp_only:
        assert environment["FASTDDS_BUILTIN_TRANSPORTS"] == "UDPv4"


def _can_make_a_namespace_with_a_link() -> bool:
    if shutil.which("ip") is None:
        return False
    probe = subprocess.run(["unshare", "-n", "ip", "link", "add", "fprv0", "type", "veth", "peer", "name", "fprv1"],
                           capture_output=True, check=False)
    return probe.returncode == 0


@pytest.mark.skipif(not _can_make_a_namespace_with_a_link(),
                    reason="needs `unshare -n` and `ip link add … type veth` (root) to build a namespace with a link")
def test_isolated_sh_does_not_trust_an_inherited_flag_where_a_link_exists(tmp_path):
    """FPR_IN_NETNS=1 set by hand (or inherited) in a namespace that has a link besides loopback: isolated.sh still
    moves the command into a private namespace with loopback only (before, the flag alone skipped the unshare)."""
    script = os.path.join(ROOT, "scripts", "isolated.sh")
    result = subprocess.run(
        ["unshare", "-n", "sh", "-c", "ip link add fprv0 type veth peer name fprv1 && "
         f"FPR_IN_NETNS=1 bash {script} sh -c 'cat /proc/self/net/dev; echo FLAG=$FPR_IN_NETNS'"],
        capture_output=True, text=True, check=True, timeout=60)
    seen = tmp_path / "net_dev"
    seen.write_text(result.stdout)
    assert network_interfaces(str(seen)) == {"lo"}, result.stdout
    assert "FLAG=1" in result.stdout


def test_isolation_line_says_where_the_traffic_can_go(tmp_path, monkeypatch):
    line, warning = isolation_line(_net_dev(tmp_path, "lo"))
    assert not warning and "nothing leaves this machine" in line
    outside = _net_dev(tmp_path, "lo", "eth0")
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    monkeypatch.setenv("ROS_DOMAIN_ID", "17")
    line, warning = isolation_line(outside)
    assert not warning and "LOCALHOST, domain 17" in line and "scripts/isolated.sh" in line
    monkeypatch.delenv("ROS_AUTOMATIC_DISCOVERY_RANGE")
    monkeypatch.delenv("ROS_DOMAIN_ID")
    line, warning = isolation_line(outside)  # Jazzy's default: the LAN sees the simulated swarm
    assert warning and line.startswith("WARNING") and "SUBNET" in line and "domain 0" in line
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "SUBNET")
    assert isolation_line(outside)[1]
