"""VMC protocol: message parsing, frame assembly and completion, Unity <-> core conversions,
the canonical <-> Unity rig round trip, and the receiver/sender over real UDP (no ROS)."""

import queue
import socket

import numpy as np
import pytest
from pythonosc.osc_message_builder import OscMessageBuilder
from scipy.spatial.transform import Rotation

from motion_style_ros.core import rotations as rot
from motion_style_ros.core.motion import Motion
from motion_style_ros.core.retarget import tpose
from motion_style_ros.core.skeleton import canonical
from motion_style_ros.errors import MotionStyleError
from motion_style_ros.io import vmc

RNG = np.random.default_rng(7)


def message(address, *args):
    builder = OscMessageBuilder(address)
    for a in args:
        builder.add_arg(a)
    return builder.build().dgram


def random_motion(n_frames=8, spread=0.4):
    """Canonical-skeleton motion: the T-pose plus random local turns and a wandering pelvis."""
    sk = canonical()
    base = tpose(sk).local_rotations
    axis = RNG.normal(size=(n_frames, sk.n_joints, 3))
    turn = rot.from_axis_angle(axis, spread * np.linalg.norm(axis, axis=-1))
    rotations = rot.multiply(base, turn)
    rotations[:, 0] = rot.identity()
    root = sk.offsets[sk.pelvis] + RNG.normal(scale=0.3, size=(n_frames, 3))
    return Motion.from_rotations(sk, rotations, root, 30.0)


def test_unity_rotation_maps_to_the_same_physical_turn():
    q_unity = Rotation.random(50, random_state=3).as_quat()  # (x, y, z, w), Hamilton like Unity
    v_unity = RNG.normal(size=(50, 3))
    turned_unity = Rotation.from_quat(q_unity).apply(v_unity)
    q_core = vmc.unity_to_core_rotation(q_unity)
    np.testing.assert_allclose(
        rot.rotate(q_core, vmc.unity_to_core_position(v_unity)),
        vmc.unity_to_core_position(turned_unity), atol=1e-12,
    )
    np.testing.assert_allclose(vmc.core_to_unity_rotation(q_core), q_unity, atol=1e-15)
    np.testing.assert_allclose(vmc.core_to_unity_position(vmc.unity_to_core_position(v_unity)), v_unity)


def test_unity_frame_semantics():
    # Unity: +X is the character's right; the core puts the left at +X.
    assert vmc.unity_to_core_position([1.0, 2.0, 3.0]).tolist() == [-1.0, 2.0, 3.0]
    # +90 degrees about Unity's Y turns forward (+Z) to the right (Unity +X), clockwise from above
    # in a left-handed frame; in the core that right side is -X.
    q = np.array([0.0, np.sin(np.pi / 4), 0.0, np.cos(np.pi / 4)])
    np.testing.assert_allclose(Rotation.from_quat(q).apply([0, 0, 1]), [1, 0, 0], atol=1e-12)
    np.testing.assert_allclose(rot.rotate(vmc.unity_to_core_rotation(q), np.array([0, 0, 1.0])), [-1, 0, 0],
                               atol=1e-12)


def test_parse_transform_accepts_v20_and_v21_root():
    name, p, q = vmc.parse_transform(["Hips", 0.1, 0.9, 0.0, 0.0, 0.0, 0.0, 2.0])
    assert name == "Hips" and p.tolist() == [0.1, 0.9, 0.0] and q.tolist() == [0, 0, 0, 1.0]
    vmc.parse_transform(["root"] + [0.0] * 6 + [1.0] + [1.0] * 3 + [0.0] * 3, extra=(0, 6))


@pytest.mark.parametrize("args", [
    ["Hips", 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],  # too few
    ["Hips", 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 5.0],  # too many for a bone
    [3, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0],  # name not a string
    ["Hips", "x", 0.0, 0.0, 0.0, 0.0, 0.0, 1.0],  # string among numbers
    ["Hips", True, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0],  # OSC true is not a number
    ["Hips", float("nan"), 0.0, 0.0, 0.0, 0.0, 0.0, 1.0],
    ["Hips", 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],  # zero quaternion
])
def test_parse_transform_rejects(args):
    with pytest.raises(vmc.VmcMessageError):
        vmc.parse_transform(args)


def test_assembler_frames_from_bundles_and_time_messages():
    frames = vmc.VmcEncoder()(random_motion(3))
    asm = vmc.VmcFrameAssembler()
    got = asm.feed_datagram(vmc.frame_bundle(frames[0], 0.5).dgram)
    assert len(got) == 1 and got[0].time == 0.5
    for b, (p, q) in frames[0].bones.items():
        np.testing.assert_allclose(got[0].bones[b][0], p, atol=1e-6)
        np.testing.assert_allclose(got[0].bones[b][1], q, atol=1e-6)
    # Loose messages: the frame ends at /VMC/Ext/T, not before.
    for b, (p, q) in frames[1].bones.items():
        assert asm.feed_datagram(message(vmc.BONE_ADDRESS, b, *map(float, p), *map(float, q))) == []
    got = asm.feed_datagram(message(vmc.TIME_ADDRESS, 1.0))
    assert len(got) == 1
    np.testing.assert_allclose(got[0].bones["LeftHand"][1], frames[1].bones["LeftHand"][1], atol=1e-6)
    assert asm.counts == {"frames": 2, "malformed": 0, "dropped": 0, "ignored": 0}


def test_missing_bones_complete_from_last_pose_and_incomplete_start_is_dropped():
    frames = vmc.VmcEncoder()(random_motion(2))
    asm = vmc.VmcFrameAssembler()
    partial = vmc.VmcFrame({b: v for b, v in frames[0].bones.items() if b != "LeftHand"})
    assert asm.feed_datagram(vmc.frame_bundle(partial, 0.0).dgram) == []
    assert asm.counts["dropped"] == 1
    assert len(asm.feed_datagram(vmc.frame_bundle(frames[0], 0.1).dgram)) == 1
    partial = vmc.VmcFrame({b: v for b, v in frames[1].bones.items() if b not in ("LeftHand", "Head")})
    (got,) = asm.feed_datagram(vmc.frame_bundle(partial, 0.2).dgram)
    for b in ("LeftHand", "Head"):  # from frame 0
        np.testing.assert_allclose(got.bones[b][1], frames[0].bones[b][1], atol=1e-6)
    np.testing.assert_allclose(got.bones["RightHand"][1], frames[1].bones["RightHand"][1], atol=1e-6)
    assert not np.allclose(frames[0].bones["LeftHand"][1], frames[1].bones["LeftHand"][1], atol=1e-3)


GARBAGE = {
    "random bytes": bytes(RNG.integers(0, 256, 200, dtype=np.uint8)),
    "empty": b"",
    "truncated bundle": vmc.frame_bundle(vmc.VmcFrame({"Hips": (np.zeros(3), np.array([0, 0, 0, 1.0]))}),
                                         0.0).dgram[:-9],
    "bone with a string for x": message(vmc.BONE_ADDRESS, "Hips", "x", 0.0, 0.0, 0.0, 0.0, 0.0, 1.0),
    "bone with too few floats": message(vmc.BONE_ADDRESS, "Hips", 0.0, 0.0),
    "time as a string": message(vmc.TIME_ADDRESS, "now"),
    "OK with a float": message(vmc.OK_ADDRESS, 1.0),
}


def test_garbage_is_counted_and_dropped():
    frames = vmc.VmcEncoder()(random_motion(2))
    asm = vmc.VmcFrameAssembler()
    asm.feed_datagram(vmc.frame_bundle(frames[0], 0.0).dgram)
    for data in GARBAGE.values():
        assert asm.feed_datagram(data) == []
    assert asm.feed_datagram(message("/VMC/Ext/Blend/Val", "Joy", 1.0)) == []
    assert asm.feed_datagram(message(vmc.BONE_ADDRESS, "LeftThumbProximal", *[0.0] * 6, 1.0)) == []
    assert asm.counts["malformed"] == len(GARBAGE)
    assert asm.counts["ignored"] == 2
    (got,) = asm.feed_datagram(vmc.frame_bundle(frames[1], 0.1).dgram)
    np.testing.assert_allclose(got.bones["Hips"][0], frames[1].bones["Hips"][0], atol=1e-6)


def test_fuzzed_packets_never_raise():
    asm = vmc.VmcFrameAssembler()
    good = vmc.frame_bundle(vmc.VmcEncoder()(random_motion(1))[0], 0.0).dgram
    for _ in range(300):
        data = np.frombuffer(good, dtype=np.uint8).copy()
        data[RNG.integers(0, len(data), 8)] = RNG.integers(0, 256, 8)  # sizes, type tags, strings
        asm.feed_datagram(data[: RNG.integers(1, len(data) + 1)].tobytes())
    assert asm.counts["malformed"] > 0


def test_encoded_tpose_is_an_identity_pose_on_a_unity_rig():
    sk = canonical()
    rest = Motion.from_rotations(sk, tpose(sk).local_rotations[None], sk.offsets[sk.pelvis][None], 30.0)
    (frame,) = vmc.VmcEncoder()(rest)
    quats = np.stack([q for _, q in frame.bones.values()])
    np.testing.assert_allclose(np.abs(quats[:, 3]), 1.0, atol=1e-9)  # T-pose = Unity's rest
    assert frame.bones["LeftUpperArm"][0][0] < 0 < frame.bones["RightUpperArm"][0][0]  # left = -X
    assert frame.bones["Head"][0][1] > 0 and frame.bones["LeftLowerLeg"][0][1] < 0


def assert_same_motion(a, b, deg=1e-6, metres=1e-9):
    err = np.degrees(rot.angle_between(a.rotations[:, 1:], b.rotations[:, 1:]))
    assert err.max() < deg, err.max()
    np.testing.assert_allclose(a.global_positions(), b.global_positions(), atol=metres)


def test_canonical_to_unity_and_back_is_exact():
    m = random_motion(10)
    back = vmc.VmcDecoder()(vmc.VmcEncoder()(m))
    assert_same_motion(back, m)


def test_decoder_refuses_a_degenerate_rig_and_builds_one_from_the_next_frame():
    m = random_motion(2)
    frames = vmc.VmcEncoder()(m)
    flat = vmc.VmcFrame({b: (np.zeros(3), q) for b, (_, q) in frames[0].bones.items()})
    decoder = vmc.VmcDecoder()
    with pytest.raises(MotionStyleError, match="zero-length legs"):
        decoder([flat])
    assert_same_motion(decoder(frames), m)


def test_root_transform_is_folded_into_the_hips():
    m = random_motion(2)
    frames = vmc.VmcEncoder()(m)
    turn = Rotation.from_euler("y", 70, degrees=True)
    shift = np.array([0.5, 0.0, -1.0])
    moved = []
    for f in frames:  # the same pose with the avatar root moved: the hips world pose moves with it
        hp, hq = f.bones["Hips"]
        bones = dict(f.bones)
        bones["Hips"] = (turn.inv().apply(hp - shift), (turn.inv() * Rotation.from_quat(hq)).as_quat())
        moved.append(vmc.VmcFrame(bones, (shift, turn.as_quat())))
    assert_same_motion(vmc.VmcDecoder()(moved), m)


def test_bandai_clip_round_trips_through_unity_bones(datasets):
    from motion_style_ros.io.datasets import index_bandai, load_clip

    info = next(i for i in index_bandai(datasets) if i.content == "walk")
    m = load_clip(info)[:40]
    assert_same_motion(vmc.VmcDecoder()(vmc.VmcEncoder()(m)), m)


def test_receiver_and_sender_over_udp():
    frames = vmc.VmcEncoder()(random_motion(5))
    got = queue.Queue()
    receiver = vmc.VmcReceiver(got.put, port=0).start()
    try:
        sender = vmc.VmcSender(*receiver.address)
        sender.send(frames[0], 0.0)
        first = got.get(timeout=10)
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as raw:
            for data in GARBAGE.values():
                raw.sendto(data, receiver.address)
        for t, f in enumerate(frames[1:], 1):
            sender.send(f, t / 30)
        received = [first] + [got.get(timeout=10) for _ in frames[1:]]
    finally:
        receiver.close()
    assert receiver.counts["malformed"] == len(GARBAGE)
    assert [f.time for f in received] == pytest.approx([t / 30 for t in range(5)])
    for f, r in zip(frames, received):
        for b, (p, q) in f.bones.items():
            np.testing.assert_allclose(r.bones[b][0], p, atol=1e-6)
            np.testing.assert_allclose(r.bones[b][1], q, atol=1e-6)
