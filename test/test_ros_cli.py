"""The README's ROS commands, run as a user runs them: ``ros2 launch``, ``ros2 param``, ``ros2 topic``,
``ros2 lifecycle`` and ``ros2 run`` against the package installed into an ament prefix
(conftest's ``ros_cli``, ``test/ros_cli.py``). One launched system serves the first tests; each
assertion reads what the CLI printed.
"""

from __future__ import annotations

import os
import re
import signal
import subprocess
import time

import pytest
import yaml

from motion_style_ros.io.joint_state import JointStateLayout
from ros_cli import DISCOVERY, error_lines

NAMES = list(JointStateLayout.canonical().names)
TRY_OUT = ["use_synthetic:=true", "markers:=true", "namespace:=demo"]  # the README's try-out


class Launched:
    """``ros2 launch motion_style_ros stylizer.launch.py ARGS``, the seconds until its first stylized
    frame arrived (``ros2 topic echo --once``), stopped with Ctrl-C by the last test."""

    def __init__(self, cli, args, topic="/demo/stylized/joint_states"):
        self.cli = cli
        start = time.monotonic()
        self.proc = cli.start("ros2", "launch", "motion_style_ros", "stylizer.launch.py", *args,
                              log="launch_" + "_".join(a.split(":=")[0] for a in args) + ".log")
        self.first = cli.first_message(topic, "sensor_msgs/msg/JointState", field="name")
        self.seconds_to_first_frame = time.monotonic() - start
        self.code = None

    def stop(self, sig=signal.SIGINT):
        self.code = self.cli.stop(self.proc, sig)
        return self.code, self.proc.log.read_text()


@pytest.fixture(scope="module")
def demo(ros_cli):
    system = Launched(ros_cli, TRY_OUT)
    yield system
    if system.code is None:
        system.stop()


def test_ros2_launch_try_out_reaches_a_stylized_frame(demo, ros_cli):
    assert yaml.safe_load(demo.first.split("---")[0]) == NAMES  # the input's names, in its order
    print(f"ros2 launch to the first stylized frame: {demo.seconds_to_first_frame:.1f} s")
    wanted = {"/demo/stylizer", "/demo/synthetic_performer"}
    nodes = ros_cli.ros2_graph("node", "list", until=lambda out: wanted <= set(out.stdout.split()))
    assert wanted <= set(nodes.stdout.split()), nodes
    markers = ros_cli.first_message("/demo/stylized/markers", "visualization_msgs/msg/MarkerArray",
                                    field="markers")
    assert "visualization_msgs.msg.Marker(" in markers, markers  # markers:=true: the skeleton for RViz


def test_ros2_param_set_get_dump_on_the_live_stylizer(demo, ros_cli):
    def param(*args):
        return ros_cli.ros2("param", *args, "--no-daemon", "--timeout", DISCOVERY)

    out = param("set", "/demo/stylizer", "target_style", "youthful")
    assert (out.returncode, out.stdout.strip()) == (0, "Set parameter successful"), out
    out = param("set", "/demo/stylizer", "alpha", "0.5")
    assert out.stdout.strip() == "Set parameter successful", out
    out = param("get", "/demo/stylizer", "target_style")
    assert out.stdout.strip() == "String value is: youthful", out
    out = param("dump", "/demo/stylizer")
    dumped = yaml.safe_load(out.stdout)["/demo/stylizer"]["ros__parameters"]
    assert (dumped["target_style"], dumped["alpha"]) == ("youthful", 0.5), out.stdout

    # Bad values are refused with the node's reason, as the CLI prints it; the old value stays.
    out = param("set", "/demo/stylizer", "target_style", "sleepy")
    assert out.stderr.startswith("Setting parameter failed: "), out
    assert "sleepy" in out.stderr and "youthful" in out.stderr, out.stderr  # what, and what is allowed
    out = param("set", "/demo/stylizer", "alpha", "7.0")
    assert out.stderr.startswith("Setting parameter failed: "), out
    out = param("set", "/demo/stylizer", "model", "other.onnx")  # read at start only
    assert out.stderr.startswith("Setting parameter failed: "), out


def hz(ros_cli, *topics, reports=3, timeout=40.0):
    """``ros2 topic hz TOPICS`` until it has printed ``reports`` rates of each topic (once a second,
    after it has discovered them), then Ctrl-C: the last average rate of each topic."""
    proc = ros_cli.start("ros2", "topic", "hz", *topics, log="hz.log")

    def rates():  # the multi-topic table: "<topic>  <rate>  <min> <max> <std> <window>"
        text = proc.log.read_text()
        return {t: re.findall(rf"^{re.escape(t)}\s+([\d.]+)\s", text, re.M) for t in topics}

    deadline = time.monotonic() + timeout
    while min(len(r) for r in rates().values()) < reports and time.monotonic() < deadline:
        time.sleep(0.25)
    ros_cli.stop(proc)
    found = rates()
    assert all(found.values()), proc.log.read_text()
    return {t: float(r[-1]) for t, r in found.items()}


def test_ros2_topic_hz_of_the_output_is_the_inputs_rate(demo, ros_cli):
    rates = hz(ros_cli, "/demo/joint_states", "/demo/stylized/joint_states")
    assert rates["/demo/joint_states"] == pytest.approx(60, rel=0.15), rates  # synthetic_performer
    assert rates["/demo/stylized/joint_states"] == pytest.approx(rates["/demo/joint_states"], rel=0.1), rates


def test_ros2_launch_stops_cleanly_on_ctrl_c(demo):
    code, log = demo.stop(signal.SIGINT)
    assert code == 0, log
    assert error_lines(log) == [], log
    assert len(re.findall(r"process has finished cleanly", log)) == 2, log  # stylizer, performer


def test_ros2_launch_managed_then_ros2_lifecycle_set_through_every_transition(ros_cli):
    """``managed:=true`` brings stylizer_managed to active; ``ros2 lifecycle set`` then walks it
    through deactivate, cleanup, configure, activate and shutdown, after which it exits by itself."""
    system = Launched(ros_cli, ["managed:=true", "use_synthetic:=true", "namespace:=demo"])
    assert yaml.safe_load(system.first.split("---")[0]) == NAMES

    # ros2 lifecycle finds a node by its lifecycle services, which a fresh --no-daemon participant
    # takes 3-12 s to discover here (on every call); a daemon of this test's own keeps the graph.
    assert ros_cli.ros2("daemon", "start").returncode == 0

    def lifecycle(*args, timeout=60):
        return ros_cli.ros2_graph("lifecycle", *args, daemon=True, timeout=timeout)

    def state():
        """The node's state; "" if the CLI has not found the node within 30 s (discovery on a busy machine)."""
        deadline = time.monotonic() + 30.0
        while True:
            words = lifecycle("get", "/demo/stylizer").stdout.split()
            if words or time.monotonic() > deadline:
                return words[0] if words else ""
            time.sleep(1.0)

    def transition(name):
        """``ros2 lifecycle set``, the node's answer checked. Fast DDS can drop that answer on a
        loaded machine (the node's response writer has not matched the CLI's fresh reader within
        its 100 ms: the node logs "failed to send response (timeout)", ros2/rmw_fastrtps#842), and
        the CLI then waits for ever, as a user would see it hang: that case passes only when the
        node said so and the transition was made all the same (the state read back)."""
        try:
            out = lifecycle("set", "/demo/stylizer", name, timeout=30)
        except subprocess.TimeoutExpired:
            assert "failed to send response (timeout)" in system.proc.log.read_text(), name
            return
        assert out.stdout.strip() == "Transitioning successful", (name, out)

    assert state() == "active"
    # after deactivate the launch file must not activate it again; every state is read back
    for name, reached in [("deactivate", "inactive"), ("cleanup", "unconfigured"), ("configure", "inactive"),
                          ("activate", "active")]:
        transition(name)
        assert state() == reached, name
    ros_cli.first_message("/demo/stylized/joint_states", "sensor_msgs/msg/JointState", field="name")
    transition("shutdown")
    deadline = time.monotonic() + 30
    while "process has finished cleanly" not in system.proc.log.read_text() and time.monotonic() < deadline:
        time.sleep(0.2)
    assert "The daemon has been stopped" in ros_cli.ros2("daemon", "stop").stdout
    code, log = system.stop()
    assert re.search(r"\[stylizer_managed-1\]: process has finished cleanly", log), log
    assert code == 0 and error_lines(log) == [], log


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT], ids=["SIGTERM", "SIGINT"])
def test_ros2_run_nodes_stop_cleanly_on_a_signal_while_streaming(ros_cli, tmp_path, sig):
    """``ros2 run`` of a performer, the stylizer, a relay and a recorder of the stylized stream;
    mid-stream each gets ``sig`` at once: SIGINT as Ctrl-C sends it (to ``ros2 run``'s whole process
    group), SIGTERM as a supervisor sends it (to the node's process). Each exits 0 without an error
    line, and the recorder's bag is readable and holds every message it reported writing."""
    import psutil

    from motion_style_ros.io.bags import read_joint_states

    ns = f"/sig_{sig.name.lower()}"
    bag = tmp_path / "stylized"
    nodes = {
        "synthetic_performer": [],
        "stylizer": [],
        "relay": ["-r", "stylized/joint_states:=relayed/joint_states"],
        "recorder": ["-p", "topics:=[stylized/joint_states]", "-p", f"bag:={bag}"],
    }
    procs = {name: ros_cli.start("ros2", "run", "motion_style_ros", name, "--ros-args", "-r",
                                 f"__ns:={ns}", *extra, log=f"{sig.name}_{name}.log")
             for name, extra in nodes.items()}
    ros_cli.first_message(f"{ns}/stylized/joint_states", "sensor_msgs/msg/JointState", field="name")
    ros_cli.first_message(f"{ns}/relayed/joint_states", "sensor_msgs/msg/JointState", field="name")
    time.sleep(1.0)  # streaming and recording
    for name, proc in procs.items():
        if sig == signal.SIGINT:
            os.killpg(proc.pid, sig)
        else:
            (child,) = psutil.Process(proc.pid).children()  # the node's process under ros2 run
            child.send_signal(sig)
    for name, proc in procs.items():
        code = ros_cli.stop(proc, None)  # the signal has been sent: wait
        log = proc.log.read_text()
        assert code == 0, (name, log)
        assert error_lines(log) == [], (name, log)
    written = re.search(r"wrote (\d+) messages to", procs["recorder"].log.read_text())
    assert written, procs["recorder"].log.read_text()
    records = read_joint_states(bag)
    assert len(records) == int(written.group(1)) > 0
    assert all(r.names == NAMES for r in records)


def test_ros2_launch_workers_share_the_performers_over_stylizer_processes(ros_cli):
    """``workers:=2 performers:="['', b]"``: stylizer_0 takes the namespace's own stream (the
    synthetic performer's), stylizer_1 performer ``b`` (a second performer, ``ros2 run``), each
    stylizes its own, and each process holds its share of the list."""
    second = ros_cli.start("ros2", "run", "motion_style_ros", "synthetic_performer", "--ros-args",
                           "-r", "__ns:=/demo/b", log="workers_performer_b.log")
    system = Launched(ros_cli, ["use_synthetic:=true", "namespace:=demo", "workers:=2",
                                "performers:=['', b]"])
    assert yaml.safe_load(system.first.split("---")[0]) == NAMES
    out = ros_cli.first_message("/demo/b/stylized/joint_states", "sensor_msgs/msg/JointState", field="name")
    assert yaml.safe_load(out.split("---")[0]) == NAMES
    for node, share in [("/demo/stylizer_0", "['']"), ("/demo/stylizer_1", "['b']")]:
        out = ros_cli.ros2("param", "get", node, "performers", "--no-daemon", "--timeout", DISCOVERY)
        assert out.stdout.strip() == f"String values are: {share}", out
    assert ros_cli.ctrl_c(second) == 0
    code, log = system.stop()
    assert code == 0 and error_lines(log) == [], log
    assert len(re.findall(r"\[stylizer-\d\]: process has finished cleanly", log)) == 2, log


def test_ros2_param_set_of_a_reference_that_cannot_serve_fails_and_the_old_value_stays(ros_cli, tmp_path):
    """A stgcn stylizer (``ros2 run``): ``ros2 param set`` of ``reference`` to a truncated BVH, to a
    BVH holding NaN, to /dev/zero and to a FIFO prints "Setting parameter failed" with the reason,
    the node reads none of them (a FIFO with no writer would block it), and ``ros2 param get`` still
    shows the clip in use ('' here)."""
    from bad_files import unusable_clips

    reasons = dict(unusable_clips(tmp_path, 30.0))
    proc = ros_cli.start("ros2", "run", "motion_style_ros", "stylizer", "--ros-args", "-p", "backend:=stgcn",
                         "-r", "__ns:=/refs", log="refs_stylizer.log")

    def param(*args):
        return ros_cli.ros2("param", *args, "--no-daemon", "--timeout", DISCOVERY)

    try:
        ros_cli.ros2_graph("node", "list", until=lambda out: "/refs/stylizer" in out.stdout.split())
        for path, reason in reasons.items():
            if not any(kind in path for kind in ("truncated", "nan", "fifo")) and path != "/dev/zero":
                continue
            out = param("set", "/refs/stylizer", "reference", path)
            assert out.stderr.startswith("Setting parameter failed: ") and reason in out.stderr, (path, out)
        out = param("get", "/refs/stylizer", "reference")
        assert out.stdout.strip() == "String value is:", out
        assert proc.poll() is None
    finally:
        code = ros_cli.ctrl_c(proc)  # as in a terminal: ros2 run waits for its node, which gets it too
    assert code == 0 and error_lines(proc.log.read_text()) == [], proc.log.read_text()
