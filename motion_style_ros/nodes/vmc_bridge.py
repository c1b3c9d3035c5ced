"""vmc_bridge: VMC (OSC over UDP) motion in, sensor_msgs/JointState out, and optionally back out.

Receives a VMC performer's stream on ``osc_host:osc_port``, retargets each complete frame to the
canonical skeleton and publishes it on ``output_topic`` in the canonical JointState layout. With
``send_port`` > 0 it also streams every JointState on ``input_topic`` (e.g. stylized motion) as VMC
to an avatar host at ``send_host:send_port``. Counters go to ``/diagnostics`` once a second.
"""

from __future__ import annotations

import threading

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rclpy.qos import qos_profile_sensor_data
from sensor_msgs.msg import JointState

from motion_style_ros.core.motion import Motion
from motion_style_ros.core.skeleton import canonical
from motion_style_ros.errors import MotionStyleError
from motion_style_ros.io.joint_state import JointStateLayout
from motion_style_ros.io.vmc import (
    DEFAULT_HOST,
    DEFAULT_PORT,
    VmcDecoder,
    VmcEncoder,
    VmcFrame,
    VmcReceiver,
    VmcSender,
)
from motion_style_ros.nodes import PlayerNode, joint_state, run


class VmcBridge(PlayerNode):
    """Bridges VMC and JointState; the conversions live in :mod:`motion_style_ros.io.vmc`."""

    def __init__(self) -> None:
        super().__init__("vmc_bridge")
        osc_host = self.param("osc_host", DEFAULT_HOST, "Address to receive VMC on.")
        osc_port = self.param("osc_port", DEFAULT_PORT, "UDP port to receive VMC on (0: any free port).",
                              0, 65535)
        send_host = self.param("send_host", DEFAULT_HOST, "Avatar host to send VMC to.")
        send_port = self.param("send_port", 0, "Avatar host's VMC port; 0 sends nothing.", 0, 65535)
        input_topic = self.param("input_topic", "stylized/joint_states",
                                 "JointState topic streamed out as VMC when send_port > 0.")
        output_topic = self.param("output_topic", "joint_states",
                                  "JointState topic the received VMC motion is published on.")
        self.frame_id = self.param("frame_id", "", "header.frame_id of the published states.")

        self.layout = JointStateLayout.canonical()
        self._decoder = VmcDecoder()
        self._lock = threading.Lock()
        self._errors = 0  # frames or states that could not be converted
        self._sent = 0
        self._last_bad = 0
        # Bind before advertising: once the publisher is visible, the port is open.
        try:
            self.receiver = VmcReceiver(self._on_frame, osc_host, osc_port)
        except OSError as exc:
            raise MotionStyleError(f"cannot receive VMC on udp://{osc_host}:{osc_port}: "
                                   f"{exc.strerror or exc}") from None
        self._publisher = self.create_publisher(JointState, output_topic, qos_profile_sensor_data)
        self._diagnostics = self.create_publisher(DiagnosticArray, "/diagnostics", 10)
        self._sender = None
        if send_port > 0:
            self._sender = VmcSender(send_host, send_port)
            self._encoder = VmcEncoder()
            self.create_subscription(JointState, input_topic, self._on_state, qos_profile_sensor_data)
        self.create_timer(1.0, self._publish_diagnostics)
        self.receiver.start()
        host, port = self.receiver.address
        self.get_logger().info(
            f"receiving VMC on udp://{host}:{port} -> {output_topic}"
            + (f"; sending {input_topic} to udp://{send_host}:{send_port}" if self._sender else "")
        )

    def _on_frame(self, frame: VmcFrame) -> None:
        """Runs on the receiver's thread."""
        try:
            motion = self._decoder([frame])
            values = self.layout.encode(motion.rotations[0], motion.root_positions[0])
            if not np.isfinite(values).all():
                raise MotionStyleError("VMC frame gave non-finite joint values")
        except MotionStyleError as exc:
            self._decoder.reset()  # the rig may come from a degenerate frame: build it anew
            with self._lock:
                self._errors += 1
            self.get_logger().warning(f"dropped a VMC frame: {exc}", throttle_duration_sec=5.0)
            return
        self._publisher.publish(
            joint_state(self.layout.names, values, self.get_clock().now().to_msg(), self.frame_id))

    def _on_state(self, msg: JointState) -> None:
        try:
            rotations, root = self.layout.decode(msg.name, msg.position)
        except MotionStyleError as exc:
            with self._lock:
                self._errors += 1
            self.get_logger().warning(f"not sent as VMC: {exc}", throttle_duration_sec=5.0)
            return
        motion = Motion.from_rotations(canonical(), rotations[None], root[None], 30.0)
        self._sender.send(self._encoder(motion)[0], self.get_clock().now().nanoseconds * 1e-9)
        with self._lock:
            self._sent += 1

    def _publish_diagnostics(self) -> None:
        counts = self.receiver.counts
        with self._lock:
            counts.update(conversion_errors=self._errors, sent=self._sent)
        bad = counts["malformed"] + counts["dropped"] + counts["conversion_errors"]
        status = DiagnosticStatus(
            level=DiagnosticStatus.WARN if bad > self._last_bad else DiagnosticStatus.OK,
            name=f"{self.get_name()}: VMC receiver",
            message=f"{counts['frames']} frames, {bad} bad so far",
            hardware_id="udp://{}:{}".format(*self.receiver.address),
            values=[KeyValue(key=k, value=str(v)) for k, v in sorted(counts.items())],
        )
        self._last_bad = bad
        array = DiagnosticArray(status=[status])
        array.header.stamp = self.get_clock().now().to_msg()
        self._diagnostics.publish(array)

    def destroy_node(self) -> None:
        self.receiver.close()
        super().destroy_node()


def main(args: list[str] | None = None) -> int:
    return run(VmcBridge, "vmc_bridge", args)


if __name__ == "__main__":
    raise SystemExit(main())
