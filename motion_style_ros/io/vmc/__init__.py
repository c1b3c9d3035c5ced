"""VMC protocol (Virtual Motion Capture v2.7, OSC over UDP): receive, assemble, convert and send.

A VMC performer (a mocap or face-tracking app) streams to a marionette (an avatar host), by
convention on UDP port 39539; the port 39540 is the convention for the other direction (a
marionette or an assistant talking to the performer) and for a second marionette on the same host.
A performer sends a frame in one bundle or in many; :class:`VmcFrameAssembler` decides where a
frame ends.

- :mod:`.protocol`: the messages, :class:`VmcFrame`, Unity's frame in the core's
- :mod:`.osc`: datagrams read and written
- :mod:`.assembly`: frames from messages, however the sender bundles them
- :mod:`.rig`: the sender's rig, frames to canonical motion and back
- :mod:`.transport`: UDP sender and receiver (live means latest)
- :mod:`.clock`: stamps that keep the sender's rhythm

What ``vmc_bridge`` does with all this is :class:`motion_style_ros.runtime.vmc_link.VmcLink`.
"""

from motion_style_ros.io.vmc.assembly import VmcFrameAssembler
from motion_style_ros.io.vmc.clock import SenderClock
from motion_style_ros.io.vmc.osc import Packet, bone_message, build_message, bundle, frame_bundle, osc_messages
from motion_style_ros.io.vmc.protocol import (
    APPLY_ADDRESS,
    BLEND_ADDRESS,
    BONE_ADDRESS,
    EXTRA_BONES,
    HUMAN_BONES,
    MAX_VALUE,
    OK_ADDRESS,
    REQUIRED_BONES,
    ROOT_ADDRESS,
    TIME_ADDRESS,
    UNITY_PARENTS,
    VmcFrame,
    VmcMessageError,
    core_to_unity_position,
    core_to_unity_rotation,
    parse_transform,
    unity_to_core_position,
    unity_to_core_rotation,
    usable,
)
from motion_style_ros.io.vmc.rig import VmcDecoder, VmcEncoder, rig_motion, root_transform, tpose_rig, unity_rig
from motion_style_ros.io.vmc.transport import (
    DEFAULT_HOST,
    DEFAULT_PORT,
    DEFAULT_SEND_PORT,
    MAX_AGE_S,
    RECEIVE_BUFFER,
    VmcReceiver,
    VmcSender,
)

__all__ = [
    "APPLY_ADDRESS", "BLEND_ADDRESS", "BONE_ADDRESS", "DEFAULT_HOST", "DEFAULT_PORT", "DEFAULT_SEND_PORT",
    "EXTRA_BONES", "HUMAN_BONES", "MAX_AGE_S", "MAX_VALUE", "OK_ADDRESS", "RECEIVE_BUFFER", "REQUIRED_BONES",
    "ROOT_ADDRESS", "TIME_ADDRESS", "UNITY_PARENTS", "Packet", "SenderClock", "VmcDecoder", "VmcEncoder",
    "VmcFrame", "VmcFrameAssembler", "VmcMessageError", "VmcReceiver", "VmcSender", "bone_message",
    "build_message", "bundle", "core_to_unity_position", "core_to_unity_rotation", "frame_bundle",
    "osc_messages", "parse_transform", "rig_motion", "root_transform", "tpose_rig", "unity_rig",
    "unity_to_core_position", "unity_to_core_rotation", "usable",
]
