"""How a node's process runs: every node's ``main`` goes through :func:`run`, so a node that cannot
start (bad file, bad parameter) logs one error line and exits with status 2, and Ctrl-C (SIGINT) or
SIGTERM ends it cleanly with status 0; the executor (``MOTION_STYLE_EXECUTOR``) and the message-info
callback wrapper both executors take."""

from __future__ import annotations

import faulthandler
import gc
import inspect
import os
import re
import signal
import sys
import tempfile
import threading
from collections.abc import Callable

import rclpy
from rclpy.exceptions import NameValidationException, ParameterException
from rclpy.executors import Executor, ExternalShutdownException, SingleThreadedExecutor
from rclpy.impl.implementation_singleton import rclpy_implementation
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions

from motion_style_ros.errors import MotionStyleError

RCLError = rclpy_implementation.RCLError
EXECUTOR_VARIABLE = "MOTION_STYLE_EXECUTOR"
EXECUTORS = ("events", "single_threaded")
SPIN_SECONDS = 0.1  # a node checks whether it is done (or shut down) at least this often
# How long a node's teardown may take once a signal asked it to stop, before its threads' stacks are
# written to stderr and it exits with status 1: under launch's escalation to SIGTERM (5 s), so that a
# teardown stuck in native code (where no Python signal handler runs) says where, and ends.
TEARDOWN_SECONDS = 4.0


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
    once (KeyboardInterrupt). The first signal also starts the teardown's watchdog
    (:data:`TEARDOWN_SECONDS`)."""

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
        if self.requested:  # only a signal sets it, and that signal started the watchdog
            faulthandler.cancel_dump_traceback_later()
        for number, previous in self._previous.items():
            signal.signal(number, previous)

    def _handle(self, number, frame) -> None:
        first, self.requested = not self.requested, True
        if first:
            faulthandler.dump_traceback_later(TEARDOWN_SECONDS, exit=True)
            if self.started:
                return
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
    node = spinner = None
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
        # The executor lets go of the node's entities before they are destroyed, and both before the
        # context: the order rclpy's own executors assume (the events executor holds each one).
        if spinner is not None:
            spinner.shutdown()
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    return 0
