"""What the live commands (``demo``, ``bench nodes``) share: node subprocesses and an rclpy node of
their own in a private ROS domain on the loopback interface.

Imported only from a command's ``run()`` (it imports rclpy). Each package node runs as its own
process, ``python -m motion_style_ros.nodes.<name> --ros-args -p k:=v``, so what is measured and
shown is what a deployment runs: separate processes talking over DDS.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.signals import SignalHandlerOptions

from motion_style_ros.errors import MotionStyleError

STARTUP_SECONDS = 90.0  # loading rclpy and ONNX Runtime in node processes on a busy machine
STOP_SECONDS = 10.0  # SIGINT, then this long to finish (the recorder finalises its bag), then kill


def ros_value(value) -> str:
    """A parameter value as ``--ros-args -p name:=<value>`` reads it (YAML): floats keep their
    point (an int would not set a double parameter), lists and strings are quoted."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return repr(value)
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(ros_value(v) if not isinstance(v, str) else repr(v) for v in value) + "]"
    return str(value)


def stamp_ns(stamp) -> int:
    return stamp.sec * 1_000_000_000 + stamp.nanosec


class LiveGraph:
    """This command's rclpy node beside the node processes it starts; a context manager that stops
    every process it started (SIGINT, then kill), on every way out, Ctrl-C and SIGTERM included.

    The domain is the command's own (from its process id) and discovery stays on loopback, so two
    runs, or a run beside the test suite, do not see each other. Node logs go to ``log_dir``.
    """

    def __init__(self, name: str, log_dir: Path) -> None:
        self.log_dir = Path(log_dir)
        self.log_dir.mkdir(parents=True, exist_ok=True)
        domain = 1 + os.getpid() % 100
        os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"  # for this process's rclpy too
        os.environ.pop("ROS_STATIC_PEERS", None)
        self.env = dict(os.environ, ROS_DOMAIN_ID=str(domain), ROS_LOG_DIR=str(self.log_dir / "ros"),
                        PYTHONUNBUFFERED="1")
        # The ROS wheels' bootstrapper sets up the child's library path itself when this is unset.
        self.env.pop("_ROS_WHEELS_BOOTSTRAP_COMPLETE", None)
        self.processes: dict[str, subprocess.Popen] = {}
        self._logs: dict[str, Path] = {}
        self._previous_sigterm = signal.signal(signal.SIGTERM, _interrupt)
        self.context = rclpy.Context()
        # No rclpy signal handlers: Ctrl-C stays a KeyboardInterrupt, so the processes get stopped.
        rclpy.init(context=self.context, domain_id=domain,
                   signal_handler_options=SignalHandlerOptions.NO)
        self.node = rclpy.create_node(name, context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)

    def start(self, node: str, name: str | None = None, remaps: dict[str, str] | None = None,
              **params) -> subprocess.Popen:
        """Start ``motion_style_ros.nodes.<node>`` (node name ``name``, topics remapped by
        ``remaps``) with ROS parameters; its console output goes to ``<log_dir>/<name>.log``."""
        name = name or node
        cmd = [sys.executable, "-m", f"motion_style_ros.nodes.{node}", "--ros-args"]
        if name != node:
            cmd += ["-r", f"__node:={name}"]
        for source, target in (remaps or {}).items():
            cmd += ["-r", f"{source}:={target}"]
        for key, value in params.items():
            cmd += ["-p", f"{key}:={ros_value(value)}"]
        log = self.log_dir / f"{name}.log"
        with open(log, "w") as out:
            self.processes[name] = subprocess.Popen(cmd, env=self.env, stdin=subprocess.DEVNULL,
                                                    stdout=out, stderr=subprocess.STDOUT)
        self._logs[name] = log
        return self.processes[name]

    def check(self) -> None:
        """Raise with the last log line of a process that has exited by itself."""
        for name, proc in self.processes.items():
            if proc.poll() is not None:
                lines = self._logs[name].read_text(errors="replace").strip().splitlines()
                last = lines[-1].strip() if lines else "no output"
                raise MotionStyleError(f"{name} exited with status {proc.returncode}: {last} "
                                       f"(log: {self._logs[name]})")

    def spin_until(self, condition: Callable[[], bool], what: str, timeout: float) -> None:
        """Spin this node until ``condition()`` holds; a process dying or the timeout is an error."""
        deadline = time.monotonic() + timeout
        while not condition():
            self.check()
            if time.monotonic() > deadline:
                raise MotionStyleError(f"timed out after {timeout:g} s waiting for {what} "
                                       f"(logs in {self.log_dir})")
            self.executor.spin_once(timeout_sec=0.01)

    def spin_for(self, seconds: float) -> None:
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            self.executor.spin_once(timeout_sec=min(0.01, max(end - time.monotonic(), 0.0)))

    def stop(self, name: str) -> int:
        """Stop one node process (:func:`stop_process`); its exit status."""
        return stop_process(self.processes.pop(name))

    def close(self) -> None:
        for name in reversed(list(self.processes)):
            self.stop(name)
        self.executor.shutdown()
        self.node.destroy_node()
        rclpy.try_shutdown(context=self.context)
        signal.signal(signal.SIGTERM, self._previous_sigterm)

    def __enter__(self) -> "LiveGraph":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def _interrupt(signum, frame):
    raise KeyboardInterrupt


def stop_process(proc: subprocess.Popen, timeout: float = STOP_SECONDS) -> int:
    """SIGINT (the nodes' clean exit), then kill after ``timeout`` seconds; the exit status."""
    if proc.poll() is None:
        proc.send_signal(signal.SIGINT)
        try:
            proc.wait(timeout)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
            # a recorder killed here leaves its bag without metadata: say so where it is seen
            print(f"{' '.join(map(str, proc.args[:3]))}... did not stop within {timeout:g} s of SIGINT: killed",
                  file=sys.stderr)
    return proc.returncode
