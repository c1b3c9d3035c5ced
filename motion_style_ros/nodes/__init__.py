"""ROS 2 nodes (with the CLI, the only layer that imports rclpy and message packages): thin shells
over core, io and runtime.

Every node's ``main`` goes through :func:`run`, so a node that cannot start (bad file, bad
parameter) logs one error line and exits with status 2, and Ctrl-C (SIGINT) or SIGTERM ends it
cleanly with status 0.
"""

from __future__ import annotations

import array
import gc
import inspect
import os
import re
import signal
import sys
import tempfile
import threading
from collections.abc import Callable, Sequence

import numpy as np
import rclpy
from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor
from rclpy.exceptions import NameValidationException, ParameterException
from rclpy.executors import Executor, ExternalShutdownException, SingleThreadedExecutor
from rclpy.impl.implementation_singleton import rclpy_implementation
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rclpy.signals import SignalHandlerOptions
from rclpy.task import Future
from sensor_msgs.msg import JointState

from motion_style_ros.errors import MotionStyleError

RCLError = rclpy_implementation.RCLError
RELIABILITY = {"best_effort": ReliabilityPolicy.BEST_EFFORT, "reliable": ReliabilityPolicy.RELIABLE}


class Parameters:
    """Parameter declaration for this package's nodes, plain or managed (a mixin of rclpy nodes)."""

    def param(self, name: str, default, description: str, low: float | None = None,
              high: float | None = None, read_only: bool = True):
        """Declare a parameter with its description and range and return its value; read-only
        unless told otherwise (nodes read those once, at start). A parameter that changes live is
        dynamically typed: the node's set-parameters callback checks its type, so that the reason
        for a rejection can name the type wanted (rclpy's names it by number)."""
        descriptor = ParameterDescriptor(description=description, read_only=read_only,
                                         dynamic_typing=not read_only)
        if low is not None and isinstance(default, int) and not isinstance(default, bool):
            descriptor.integer_range = [IntegerRange(from_value=int(low), to_value=int(high), step=1)]
        elif low is not None:
            descriptor.floating_point_range = [FloatingPointRange(from_value=float(low),
                                                                  to_value=float(high))]
        if self.has_parameter(name):  # a managed node configured again
            return self.get_parameter(name).value
        return self.declare_parameter(name, default, descriptor).value

    def stream_qos(self, depth: int = 10) -> QoSProfile:
        """The QoS of a node's JointState streams, from its ``qos_reliability`` and ``qos_depth``
        (``depth`` is the default: a recorder wants a deeper queue than a stylizer)."""
        return self.qos("qos", "best_effort", depth, "the streams (best_effort: sensor data; matches "
                        "every peer)")

    def qos(self, prefix: str, reliability: str, depth: int, what: str) -> QoSProfile:
        """A QoS from the parameters ``<prefix>_reliability`` and ``<prefix>_depth``."""
        reliability = self.param(f"{prefix}_reliability", reliability, f"QoS reliability of {what}: "
                                 "best_effort or reliable")
        depth = self.param(f"{prefix}_depth", depth, f"QoS history depth of {what}", 1, 1000)
        if reliability not in RELIABILITY:
            raise MotionStyleError(f"parameter {prefix}_reliability is {reliability!r}; allowed: "
                                   f"{', '.join(RELIABILITY)}")
        return QoSProfile(depth=depth, reliability=RELIABILITY[reliability])


class PlayerNode(Parameters, Node):
    """A node that may finish on its own: ``done`` completes when it has nothing more to do."""

    def __init__(self, name: str) -> None:
        super().__init__(name)
        self.done = Future()


def prefixed(prefix: str, name: str) -> str:
    """A performer's topic: ``name`` under its ``prefix`` (``''``: the node's namespace)."""
    return f"{prefix.rstrip('/')}/{name}" if prefix else name


def joint_state(names: Sequence[str], positions: np.ndarray, stamp, frame_id: str = "") -> JointState:
    msg = JointState(name=list(names), position=doubles(positions))
    msg.header.stamp = stamp
    msg.header.frame_id = frame_id
    return msg


def doubles(values: np.ndarray) -> array.array:
    """A float64 sequence field's value: an ``array('d')`` is taken as it is, where a list is
    checked element by element (3.7 against 5.4-9.9 us for a 66-joint JointState here)."""
    return array.array("d", np.ascontiguousarray(values, dtype=np.float64).tobytes())


EXECUTOR_VARIABLE = "MOTION_STYLE_EXECUTOR"
EXECUTORS = ("events", "single_threaded")
SPIN_SECONDS = 0.1  # a node checks whether it is done (or shut down) at least this often


def executor_choice() -> str:
    """Which executor the nodes spin in: ``events`` (rclpy's ``EventsExecutor``, where this rclpy
    has it, Kilted on: it takes and dispatches in C++, which halves a relay node's CPU at 16-32
    streams here, docs/models.md) or ``single_threaded``; ``MOTION_STYLE_EXECUTOR=single_threaded``
    picks the latter anyway."""
    choice = os.environ.get(EXECUTOR_VARIABLE, "events")
    if choice not in EXECUTORS:
        raise MotionStyleError(f"{EXECUTOR_VARIABLE} is {choice!r}; allowed: {', '.join(EXECUTORS)}")
    if choice == "events":
        try:
            from rclpy.experimental import EventsExecutor  # noqa: F401
        except ImportError:  # rclpy before Kilted
            return "single_threaded"
    return choice


def executor() -> Executor:
    """A new executor of :func:`executor_choice`'s kind."""
    if executor_choice() == "events":
        from rclpy.experimental import EventsExecutor

        return EventsExecutor()
    return SingleThreadedExecutor()


class WithInfo:
    """A subscription callback ``fn(msg, info)`` that gets the message info under either executor:
    rclpy 9.1's ``EventsExecutor`` calls a callback that takes message info with one ``(msg,
    info)`` tuple, where the ``SingleThreadedExecutor`` passes two arguments."""

    __signature__ = inspect.Signature([inspect.Parameter(n, inspect.Parameter.POSITIONAL_ONLY)
                                       for n in ("msg", "info")])

    def __init__(self, fn: Callable) -> None:
        self.fn = fn

    def __call__(self, *args) -> None:
        msg, info = args if len(args) == 2 else args[0]
        self.fn(msg, info)


def _init(args) -> None:
    """``rclpy.init``; when it fails, rcl's own log line on stderr ("Failed to parse global
    arguments") is held back, so that the error it raises is the one line the user sees."""
    sys.stderr.flush()
    saved = os.dup(2)
    with tempfile.TemporaryFile() as held:
        os.dup2(held.fileno(), 2)
        try:
            # No rclpy signal handlers: they shut the context down from inside the signal, while a
            # callback may still publish and the node's own teardown still logs (rosout), which
            # then fail ("publisher's context is invalid"). run() installs its own (_Stop).
            rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
        except RCLError:
            raise
        else:
            held.seek(0)
            os.write(saved, held.read())  # a successful init's output, as it would have been
        finally:
            os.dup2(saved, 2)
            os.close(saved)


def _one_line(exc: Exception) -> str:
    """An error's message on one line, without rcl's C source locations."""
    return re.sub(r",? at /\S+:\d+", "", " ".join(str(exc).split()))


class _Stop:
    """SIGINT and SIGTERM handlers for :func:`run`, restored on exit. Once the node spins, a signal
    only asks the loop to stop: the callback in progress finishes, the node is destroyed (its
    teardown may still log and publish, a recorder closes its bag) and only then is the context
    shut down. Before that (the node still being built) and on a second signal, it interrupts at
    once (KeyboardInterrupt)."""

    SIGNALS = (signal.SIGINT, signal.SIGTERM)

    def __init__(self) -> None:
        self.requested = False
        self.started = False
        self._previous = {}

    def __enter__(self) -> _Stop:
        if threading.current_thread() is not threading.main_thread():
            return self  # signal handlers belong to the main thread: a node run elsewhere has none
        for number in self.SIGNALS:
            self._previous[number] = signal.signal(number, self._handle)
        return self

    def __exit__(self, *exc) -> None:
        for number, previous in self._previous.items():
            signal.signal(number, previous)

    def _handle(self, number, frame) -> None:
        if self.started and not self.requested:
            self.requested = True
            return
        self.requested = True
        raise KeyboardInterrupt


def run(make_node: Callable[[], Node], name: str, args=None) -> int:
    """Init, build the node (``name`` is its default node name, for the log before it exists), spin
    until it is done or interrupted (SIGINT or SIGTERM: exit 0 once the node is torn down); 2 when
    it cannot start (bad ROS arguments or parameter files included: rclpy.init's error; a topic name
    rcl refuses)."""
    with _Stop() as stop:
        return _run(make_node, name, args, stop)


def _run(make_node: Callable[[], Node], name: str, args, stop: _Stop) -> int:
    try:
        _init(args)
    except RCLError as exc:
        rclpy.logging.get_logger(name).error(f"cannot start: {_one_line(exc)}")
        return 2
    except KeyboardInterrupt:
        rclpy.try_shutdown()
        return 0
    node = None
    try:
        node = make_node()
        # What the node built to start with (rclpy, ONNX Runtime, the models) lives as long as the
        # node. Frozen, it is out of the collector's way: a full collection in the stylizer then
        # takes 0.01 ms instead of 9-14 ms, which would otherwise fall in the middle of a stream.
        gc.collect()
        gc.freeze()
        spinner = executor()
        spinner.add_node(node)
        stop.started = True
        while not stop.requested and node.context.ok() and not node.done.done():
            spinner.spin_once(timeout_sec=SPIN_SECONDS)
    except (MotionStyleError, ParameterException, NameValidationException, RCLError,
            UnicodeDecodeError) as exc:
        (node.get_logger() if node else rclpy.logging.get_logger(name)).error(_one_line(exc))
        return 2
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    return 0
