"""vmc_bridge: VMC (OSC over UDP) in, sensor_msgs/JointState out, and stylized JointStates back out
as VMC on the sender's own rig.

Receives a VMC performer's stream on ``osc_host:osc_port`` (39539, where a marionette listens by
VMC convention) and publishes each complete frame on ``output_topic``, stamped by the sender's
``/VMC/Ext/T`` when it advances (else on arrival; :class:`~motion_style_ros.io.vmc.SenderClock`): the body in the canonical
JointState layout, the fingers, eyes and jaw as ``<UnityBone>_rx/_ry/_rz`` beside it (the stylizer
passes them through with the pose they came with), and the frame's blendshapes as a JointState of
their own on ``blendshape_topic`` (name = blendshape key, position = value) with the same stamp.
With ``send_port`` > 0 (39540 by default, the convention for a second marionette on one host) it
streams every JointState on ``input_topic`` back out as VMC: the stylized body on the sender's rig,
and the fingers, eyes, jaw, blendshapes, OK and ``/VMC/Thru`` messages of the frame whose pose that
output shows, as they came (:class:`motion_style_ros.runtime.vmc_link.VmcLink`). Which frame that is comes
from the stylizer's output latency (``stylizer_latency``, or read from the stylizer's own
``/diagnostics``). Counters go to ``/diagnostics`` once a second.
"""

from __future__ import annotations

import threading
import time

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rclpy.time import Time
from sensor_msgs.msg import JointState

from motion_style_ros.errors import MotionStyleError
from motion_style_ros.io.vmc import (
    DEFAULT_HOST,
    DEFAULT_PORT,
    DEFAULT_SEND_PORT,
    MAX_AGE_S,
    SenderClock,
    VmcFrame,
    VmcReceiver,
    VmcSender,
)
from motion_style_ros.nodes.messages import joint_state
from motion_style_ros.nodes.parameters import PlayerNode
from motion_style_ros.nodes.process import run
from motion_style_ros.runtime.vmc_link import VmcLink

BAD = ("malformed", "incomplete", "conversion_errors", "not_sent", "kernel_dropped", "stale", "superseded",
       "overflow", "repeated")


class VmcBridge(PlayerNode):
    """Bridges VMC and JointState; the conversions live in :mod:`motion_style_ros.io.vmc`."""

    def __init__(self) -> None:
        super().__init__("vmc_bridge")
        osc_host = self.param("osc_host", DEFAULT_HOST, "Address to receive VMC on.")
        osc_port = self.param("osc_port", DEFAULT_PORT, "UDP port to receive VMC on (39539: the VMC "
                              "marionette convention; 0: any free port).", 0, 65535)
        send_host = self.param("send_host", DEFAULT_HOST, "Avatar host to send VMC to.")
        send_port = self.param("send_port", DEFAULT_SEND_PORT, "Avatar host's VMC port (39540: the "
                               "convention for a second marionette on one host); 0 sends nothing.",
                               0, 65535)
        input_topic = self.param("input_topic", "stylized/joint_states",
                                 "JointState topic streamed out as VMC when send_port > 0.")
        output_topic = self.param("output_topic", "joint_states",
                                  "JointState topic the received VMC motion is published on.")
        blend_topic = self.param("blendshape_topic", "blendshapes", "JointState topic of the received "
                                 "blendshapes (name = key, position = value), stamped as the pose.")
        self.frame_id = self.param("frame_id", "", "header.frame_id of the published states.")
        self.latency = self.param("stylizer_latency", -1.0, "seconds by which the pose of a state on "
                                  "input_topic trails its stamp (the stylizer's output latency); "
                                  "-1 = read it from the stylizer's /diagnostics (0 until it comes)",
                                  -1.0, 10.0)
        max_age = self.param("max_age_s", MAX_AGE_S, "live bound: a datagram or frame that waited "
                             "longer than this to be handled is dropped for the newest (counted as "
                             "stale, superseded)", 0.001, 10.0)
        qos = self.stream_qos()

        self.link = VmcLink()
        self._sender_clock = SenderClock()
        self._lock = threading.Lock()
        self._counts = dict.fromkeys(("conversion_errors", "sent", "not_sent"), 0)
        self._last_bad = 0
        self._lag_max = 0.0  # ms: the most a frame's stamp lay before its publication
        self._start_ns = time.time_ns()  # /VMC/Ext/T goes out as seconds since this
        self._delay_ns = max(0, round(self.latency * 1e9))
        self._output = output_topic
        self._sender = None
        if send_port > 0:
            try:
                self._sender = VmcSender(send_host, send_port)
            except OSError as exc:
                raise MotionStyleError(f"cannot send VMC to udp://{send_host}:{send_port}: "
                                       f"{exc.strerror or exc}") from None
        # Bind before advertising: once the publisher is visible, the port is open.
        try:
            self.receiver = VmcReceiver(self._on_frame, osc_host, osc_port, max_age=max_age)
        except OSError as exc:
            raise MotionStyleError(f"cannot receive VMC on udp://{osc_host}:{osc_port}: "
                                   f"{exc.strerror or exc}") from None
        self._publisher = self.create_publisher(JointState, output_topic, qos)
        self._blend_publisher = self.create_publisher(JointState, blend_topic, qos)
        self._diagnostics = self.create_publisher(DiagnosticArray, "/diagnostics", 10)
        if self._sender:
            self.create_subscription(JointState, input_topic, self._on_state, qos)
            if self.latency < 0:
                self.create_subscription(DiagnosticArray, "/diagnostics", self._on_diagnostics, 10)
        self.create_timer(1.0, self._publish_diagnostics)
        self.receiver.start()
        host, port = self.receiver.address
        self.get_logger().info(
            f"receiving VMC on udp://{host}:{port} -> {output_topic}, {blend_topic}"
            + (f"; sending {input_topic} to udp://{send_host}:{send_port}" if self._sender else ""))

    def _on_frame(self, frame: VmcFrame) -> None:
        """Runs on the receiver's frame thread; the frame is stamped as of its arrival."""
        now = self.get_clock().now().nanoseconds
        arrived = now - (time.monotonic_ns() - frame.received_ns if frame.received_ns is not None else 0)
        stamp = Time(nanoseconds=self._sender_clock.stamp(frame.time, arrived))
        try:
            out = self.link.receive(frame, stamp.nanoseconds)
        except MotionStyleError as exc:
            with self._lock:
                self._counts["conversion_errors"] += 1
            self.get_logger().warning(f"dropped a VMC frame: {exc}", throttle_duration_sec=5.0)
            return
        if out is None:  # the sender says the pose is not the performer's (OK state): counted
            return
        lag_ms = (self.get_clock().now().nanoseconds - stamp.nanoseconds) * 1e-6
        with self._lock:
            self._lag_max = max(self._lag_max, lag_ms)
        stamp_msg = stamp.to_msg()
        self._publisher.publish(joint_state(out[0], out[1], stamp_msg, self.frame_id))
        if frame.blendshapes:
            self._blend_publisher.publish(joint_state(*self.link.blendshapes(frame), stamp_msg,
                                                      self.frame_id))

    def _on_state(self, msg: JointState) -> None:
        stamp_ns = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
        try:
            bundle = self.link.send(msg.name, msg.position, stamp_ns, self._delay_ns,
                                    (stamp_ns - self._start_ns) * 1e-9)
        except MotionStyleError as exc:
            with self._lock:
                self._counts["not_sent"] += 1
            self.get_logger().warning(f"not sent as VMC: {exc}", throttle_duration_sec=5.0)
            return
        self._sender.send_packet(bundle)
        with self._lock:
            self._counts["sent"] += 1

    def _on_diagnostics(self, msg: DiagnosticArray) -> None:
        """The stylizer's output latency for the stream this bridge publishes."""
        topic = self.resolve_topic_name(self._output)
        for status in msg.status:
            values = {kv.key: kv.value for kv in status.values}
            if values.get("input") == topic and "output_latency_ms" in values:
                try:
                    self._delay_ns = round(float(values["output_latency_ms"]) * 1e6)
                except ValueError:
                    pass

    def _publish_diagnostics(self) -> None:
        counts = self.receiver.counts
        with self._lock:
            counts.update(self._counts)
        counts.update(self.link.counts)
        counts.update(receive_buffer_bytes=self.receiver.buffer_bytes,
                      stylizer_latency_ms=f"{self._delay_ns * 1e-6:.3f}",
                      stamp_lag_max_ms=f"{self._lag_max:.1f}")
        bad = sum(counts.get(k, 0) for k in BAD)
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
        if hasattr(self, "receiver"):  # none when the bridge could not start
            self.receiver.close()
        if getattr(self, "_sender", None) is not None:
            self._sender.close()
        super().destroy_node()


def main(args: list[str] | None = None) -> int:
    return run(VmcBridge, "vmc_bridge", args)


if __name__ == "__main__":
    raise SystemExit(main())
