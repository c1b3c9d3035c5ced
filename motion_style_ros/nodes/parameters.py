"""What every node of the package declares its parameters through: :class:`Parameters` (a value
with its range and description, checked once, and the QoS parameters) and :class:`PlayerNode` (a
node that finishes on its own)."""

from __future__ import annotations

from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rclpy.task import Future

from motion_style_ros.errors import MotionStyleError

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
