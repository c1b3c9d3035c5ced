"""``stylizer_managed``: the stylizer as a managed (lifecycle) node, as ROS 2 mocap drivers such as
mocap4ros2 run: ``configure`` reads the parameters, loads the model and builds the sessions,
``activate`` subscribes to the streams, ``deactivate`` stops them (nothing is published, the
streams start afresh on the next activation), ``cleanup`` frees it all, ``shutdown`` ends the
process. A transition that fails logs its one-line reason and leaves the node unconfigured.
Everything else is the plain ``stylizer``'s (``motion_style_ros.nodes.stylizer``)."""

from __future__ import annotations

import sys

from rclpy.exceptions import ParameterException
from rclpy.lifecycle import LifecycleNode, LifecycleState, TransitionCallbackReturn
from rclpy.task import Future

from motion_style_ros.errors import MotionStyleError
from motion_style_ros.nodes.process import run
from motion_style_ros.nodes.stylizer import NAME, StylizerBase


class ManagedStylizer(StylizerBase, LifecycleNode):
    """The managed node (``stylizer_managed``): configure reads the parameters, loads the model
    and builds the sessions; activate subscribes to the streams; deactivate stops them (nothing is
    published); cleanup frees it all. A transition that fails logs its one-line reason."""

    def __init__(self) -> None:
        LifecycleNode.__init__(self, NAME)
        self.done = Future()
        self._setup()

    def on_configure(self, state: LifecycleState) -> TransitionCallbackReturn:
        try:
            self._configure()
        except (MotionStyleError, ParameterException, UnicodeDecodeError) as exc:
            self.get_logger().error(f"cannot configure: {' '.join(str(exc).split())}")
            self.performers = []
            return TransitionCallbackReturn.FAILURE
        return TransitionCallbackReturn.SUCCESS

    def on_activate(self, state: LifecycleState) -> TransitionCallbackReturn:
        self._activate()
        return TransitionCallbackReturn.SUCCESS

    def on_deactivate(self, state: LifecycleState) -> TransitionCallbackReturn:
        self._deactivate()
        return TransitionCallbackReturn.SUCCESS

    def on_cleanup(self, state: LifecycleState) -> TransitionCallbackReturn:
        self._cleanup()
        return TransitionCallbackReturn.SUCCESS

    def on_shutdown(self, state: LifecycleState) -> TransitionCallbackReturn:
        if self.performers:
            self._cleanup()
        self.done.set_result(True)
        return TransitionCallbackReturn.SUCCESS


def main(args=None) -> int:
    return run(ManagedStylizer, NAME, args)


if __name__ == "__main__":
    sys.exit(main())
