"""Helpers for tests that run nodes as real processes and talk to them over DDS from a test node
(the launch_testing pattern, by hand)."""

import subprocess
import sys
import time

import numpy as np
import pytest
import rclpy
from builtin_interfaces.msg import Time
from rcl_interfaces.srv import SetParameters
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState

from motion_style_ros.cli.live import stop_process
from motion_style_ros.nodes.stylizer import stamp_seconds

TIMEOUT = 60.0  # generous bound for readiness on a loaded machine; never a timing assertion
RESEND_AFTER = 5.0  # a service request unanswered this long is sent again (Listener.call)
BEST_EFFORT = QoSProfile(depth=1000, reliability=ReliabilityPolicy.BEST_EFFORT)


def start_node(name, env, log=None, remaps=None, **params):
    """``python -m motion_style_ros.nodes.<name> --ros-args [-r from:=to ...] -p key:=value ...``
    as a process; its output goes to the file ``log`` if given, else to pipes."""
    cmd = [sys.executable, "-m", f"motion_style_ros.nodes.{name}", "--ros-args"]
    for old, new in (remaps or {}).items():
        cmd += ["-r", f"{old}:={new}"]
    for key, value in params.items():
        cmd += ["-p", f"{key}:={value}"]
    if log is None:
        return subprocess.Popen(cmd, env=env, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                                stderr=subprocess.PIPE, text=True)
    with open(log, "w") as out:  # the process keeps its own copy of the file
        return subprocess.Popen(cmd, env=env, stdin=subprocess.DEVNULL, stdout=out,
                                stderr=subprocess.STDOUT, text=True)


def stop(proc, timeout=20.0):
    """SIGINT (a clean shutdown), then kill if it hangs; the exit code."""
    return stop_process(proc, timeout)


def message(stamp_ns, names, positions):
    """A JointState stamped ``stamp_ns`` (nanoseconds)."""
    msg = JointState(name=list(names), position=[float(v) for v in positions])
    msg.header.stamp = Time(sec=stamp_ns // 10**9, nanosec=stamp_ns % 10**9)
    return msg


def replay(session, layout, frames, controls=None):
    """What ``session`` (fresh, as the node builds it) makes of ``(stamp ns, positions)`` frames,
    stamps converted as the node converts them: per frame (JointState positions, rotations, root);
    ``controls[k](session)`` runs before frame k."""
    out = []
    for k, (stamp_ns, positions) in enumerate(frames):
        if controls and k in controls:
            controls[k](session)
        q, r = session.step(*layout.decode(layout.names, positions),
                            stamp_seconds(Time(sec=stamp_ns // 10**9, nanosec=stamp_ns % 10**9)))
        out.append((layout.encode(q, r), q, r))
    return out


def difference(a, b, layout):
    """Largest difference of two position arrays, angles compared modulo 2 pi."""
    d = np.asarray(a) - np.asarray(b)
    d[..., layout.angular] = np.mod(d[..., layout.angular] + np.pi, 2 * np.pi) - np.pi
    return float(np.abs(d).max())


def stamps(messages):
    """header.stamp of each message in nanoseconds."""
    return np.array([m.header.stamp.sec * 10**9 + m.header.stamp.nanosec for m in messages])


class Listener:
    """A test node in its own context: subscribe, publish, call services, spin until a condition
    holds."""

    def __init__(self, name="test_listener"):
        self.context = rclpy.Context()
        rclpy.init(context=self.context)
        self.node = rclpy.create_node(name, context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.received: dict[str, list] = {}
        self.subscriptions = {}

    def subscribe(self, topic, msg_type=JointState, qos=BEST_EFFORT):
        """The list that every message on ``topic`` is appended to."""
        self.received[topic] = []
        self.subscriptions[topic] = self.node.create_subscription(
            msg_type, topic, self.received[topic].append, qos)
        return self.received[topic]

    def spin_until(self, condition, what, timeout=TIMEOUT, procs=()):
        deadline = time.monotonic() + timeout
        while not condition():
            for proc in procs:
                if proc.poll() not in (None, 0):
                    output = proc.stderr.read() if proc.stderr else ""
                    pytest.fail(f"{what}: process exited with {proc.returncode}: {output}")
            if time.monotonic() > deadline:
                pytest.fail(f"timed out waiting for {what}")
            self.executor.spin_once(timeout_sec=0.05)

    def spin_for(self, seconds):
        """Spin for ``seconds`` (paces a publisher; lets messages in flight arrive)."""
        deadline = time.monotonic() + seconds
        while (left := deadline - time.monotonic()) > 0:
            self.executor.spin_once(timeout_sec=min(left, 0.05))

    def spin_while_running(self, proc):
        """Spin until ``proc`` exits by itself, then a little longer for messages still in flight."""
        deadline = time.monotonic() + TIMEOUT
        while proc.poll() is None and time.monotonic() < deadline:
            self.executor.spin_once(timeout_sec=0.05)
        for _ in range(20):
            self.executor.spin_once(timeout_sec=0.05)

    def call(self, client, request, procs=(), resend_after=RESEND_AFTER):
        """A service's response (waits for the service to appear, then for the answer).

        Fast DDS drops a response when the server has not yet matched the client's response reader
        (it waits 100 ms: "failed to send response (timeout)", ros2/ros2#1253), which a loaded
        machine hits on a client's first call. So a request with no answer after ``resend_after``
        seconds is sent again (the earlier one forgotten); give None for a request that must not run
        twice (a lifecycle transition), after an idempotent call to the same node has matched.
        """
        self.spin_until(client.service_is_ready, f"service {client.srv_name}", procs=procs)
        future = client.call_async(request)
        sent = time.monotonic()

        def answered():
            nonlocal future, sent
            if not future.done() and resend_after is not None and time.monotonic() - sent > resend_after:
                client.remove_pending_request(future)
                future, sent = client.call_async(request), time.monotonic()
            return future.done()

        self.spin_until(answered, f"an answer from {client.srv_name}", procs=procs)
        return future.result()

    def close(self):
        self.executor.shutdown()
        self.node.destroy_node()
        rclpy.try_shutdown(context=self.context)


def parameter_setter(listener, client, diagnostics, proc):
    """``set_parameters(**values)`` for a stylizer node: set them through ``client`` (its
    set_parameters service); once accepted, wait until the node's ``diagnostics`` (a subscription's
    message list) report them in use (a reference clip is read on a worker thread and applied
    after). Returns the results."""
    def set_parameters(**values):
        request = SetParameters.Request(
            parameters=[Parameter(k, value=v).to_parameter_msg() for k, v in values.items()])
        results = listener.call(client, request, procs=[proc]).results
        if all(r.successful for r in results):
            diagnostics.clear()
            listener.spin_until(lambda: any(
                all({kv.key: kv.value for kv in st.values}.get(k) == str(v) for k, v in values.items())
                for a in diagnostics for st in a.status), f"{values} in use", procs=[proc])
        return results

    return set_parameters
