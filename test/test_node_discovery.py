"""Issue #25, symptom 3: the 12-joint robot node is discoverable by another process on a loaded machine, and the
DDS sockets stay on loopback with the shipped transport profile (config/fastdds_localhost.xml, set by
conftest.py). The node runs as a program (the pip console script's code) in its own process, a second process
waits for it; busy-loop processes load the machine for the test's duration only. The bound (DISCOVERY_LIMIT_S)
only says "found at all": the 5 s target is a figure of benchmarks/bench_discovery.py, never a timed
assertion here."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

pytest.importorskip("rclpy")

from conftest import FASTDDS_PROFILE, next_domain_id  # noqa: E402

pytestmark = [pytest.mark.ros, pytest.mark.slow]

#: give up (the test fails) when the second process has not found the node after this long
DISCOVERY_LIMIT_S = 30.0
#: busy-loop processes beside the node: a load of about 4 on top of whatever runs
BUSY_PROCESSES = 4
JOINTS = [f"j{k}" for k in range(12)]

PROBE = r"""
import json, sys, time
import rclpy
from rclpy.node import Node
name, topic, limit = sys.argv[1], sys.argv[2], float(sys.argv[3])
rclpy.init()
node = Node("discovery_probe")
t0 = time.monotonic()
found = {}
while time.monotonic() - t0 < limit and len(found) < 2:
    if "node" not in found and any(n == name for n, _ in node.get_node_names_and_namespaces()):
        found["node"] = time.monotonic() - t0
    if "publisher" not in found and node.count_publishers(topic) > 0:
        found["publisher"] = time.monotonic() - t0
    time.sleep(0.02)
print(json.dumps(found), flush=True)
"""


def child_env() -> dict:
    env = dict(os.environ)   # (conftest.py set ROS_AUTOMATIC_DISCOVERY_RANGE and the Fast DDS profile)
    env["ROS_DOMAIN_ID"] = str(next_domain_id())
    env.pop("_ROS_WHEELS_BOOTSTRAP_COMPLETE", None)
    return env


def start_node(env: dict) -> tuple[subprocess.Popen, threading.Event, list[str]]:
    args = ["--ros-args", "-p", f"joints:=[{', '.join(JOINTS)}]"]
    for name in JOINTS:
        args += ["-p", f"joint.{name}.preset:=ak80_9"]
    node = subprocess.Popen([sys.executable, "-c", "import sys; from bldc_actuator.node import main; "
                             "sys.exit(main(sys.argv))", *args], env=env, stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True)
    running, log = threading.Event(), []

    def read():
        for line in node.stdout:
            log.append(line)
            if "running:" in line:
                running.set()

    threading.Thread(target=read, daemon=True).start()
    return node, running, log


def stop(proc: subprocess.Popen) -> None:
    if proc.poll() is None:
        proc.send_signal(signal.SIGINT)
        try:
            proc.wait(timeout=30)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


def udp_sockets(pid: int) -> list[str]:
    """Local addresses of the UDP sockets of process ``pid`` (``ss -ulpn``)."""
    out = subprocess.run(["ss", "-ulpn"], capture_output=True, text=True, timeout=30).stdout
    return [line.split()[3] for line in out.splitlines() if f",pid={pid}," in line]


def test_a_second_process_discovers_the_robot_node_on_a_loaded_machine():
    env = child_env()
    busy = [subprocess.Popen([sys.executable, "-c", "while True: pass"], env=env) for _ in range(BUSY_PROCESSES)]
    node = None
    try:
        node, running, log = start_node(env)
        assert running.wait(180), "the node did not start:\n" + "".join(log)
        probe = subprocess.run([sys.executable, "-c", PROBE, "bldc_actuator", "/joint_states",
                                str(DISCOVERY_LIMIT_S)], env=env, capture_output=True, text=True,
                               timeout=DISCOVERY_LIMIT_S + 180)
        assert probe.returncode == 0, probe.stderr
        found = json.loads(probe.stdout.strip().splitlines()[-1])
        load = Path("/proc/loadavg").read_text().split()[0]
        print(f"discovered after {found} s at load average {load} with {BUSY_PROCESSES} busy loops")
        assert "node" in found and "publisher" in found, \
            f"not found within {DISCOVERY_LIMIT_S:g} s: {found}; node log:\n{''.join(log)[-3000:]}"
        assert node.poll() is None, "".join(log)
    finally:
        for b in busy:
            b.kill()
            b.wait()
        if node is not None:
            stop(node)


@pytest.mark.skipif(subprocess.run(["which", "ss"], capture_output=True).returncode != 0, reason="no ss (iproute2)")
def test_the_transport_profile_keeps_the_listening_sockets_on_loopback():
    """With config/fastdds_localhost.xml every socket a peer can reach by its well-known DDS port (the
    participant's discovery and user-data unicast ports) is bound to 127.0.0.1; without it they are on 0.0.0.0."""
    assert os.environ.get("FASTDDS_DEFAULT_PROFILES_FILE") == str(FASTDDS_PROFILE)
    env = child_env()
    domain = int(env["ROS_DOMAIN_ID"])
    ports = {7400 + 250 * domain + 10 + 2 * k for k in range(20)} | {7400 + 250 * domain + 11 + 2 * k for k in range(20)}

    def listening(env) -> list[str]:
        node, running, log = start_node(env)
        try:
            assert running.wait(180), "the node did not start:\n" + "".join(log)
            return [a for a in udp_sockets(node.pid) if int(a.rsplit(":", 1)[1]) in ports]
        finally:
            stop(node)

    with_profile = listening(env)
    assert with_profile and all(a.startswith("127.0.0.1:") for a in with_profile), with_profile
    bare = dict(env)
    bare.pop("FASTDDS_DEFAULT_PROFILES_FILE")
    bare.pop("FASTRTPS_DEFAULT_PROFILES_FILE", None)
    without = listening(bare)
    assert without and not all(a.startswith("127.0.0.1:") for a in without), without   # what the profile fixes


def test_the_robot_topics_exist_while_the_kernel_compiles(ros_context, monkeypatch):
    """The issue's undiscoverable node was a first start: numba compiles the kernel (8 s of CPU, 116 s of wall
    time at load 14, `bench_discovery.py --cold-cache --probe-first`) and the node created its publishers only
    after that, so a second process found the node's name but no /joint_states for two minutes. Whatever the
    compile costs, joint_states, diagnostics and the command topics exist before it starts: here, at the moment
    the node asks for the kernel, the graph (the same context, no discovery delay) shows them."""
    from rclpy.node import Node

    import bldc_actuator.node as node_module
    from bldc_actuator.node import ActuatorNode

    probe = Node("compile_probe", context=ros_context)
    seen = {}

    def warm_up_seen_from_the_graph() -> float:
        seen["joint_states publishers"] = probe.count_publishers("/joint_states")
        seen["diagnostics publishers"] = probe.count_publishers("/diagnostics")
        seen["commands subscriptions"] = probe.count_subscribers("/bldc_actuator/commands")
        return 0.0

    monkeypatch.setattr(node_module, "warm_up", warm_up_seen_from_the_graph)
    node = ActuatorNode(context=ros_context, start=False)
    try:
        assert seen == {"joint_states publishers": 1, "diagnostics publishers": 1, "commands subscriptions": 1}
    finally:
        node.destroy_node()
        probe.destroy_node()
