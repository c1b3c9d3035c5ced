"""VMC protocol: message parsing, frame assembly however senders bundle, Unity <-> core conversions,
the canonical <-> Unity rig round trip, rigs of other proportions and rest poses, the bridge's
in/out link (every bone back as sent), and the receiver/sender over real UDP (no ROS)."""

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
from motion_style_ros.io.joint_state import rotations_from_values
from motion_style_ros.runtime.vmc_link import VmcLink
from vmc_helpers import sender_frames, unity_humanoid

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
    assert asm.counts == {"frames": 2, "malformed": 0, "incomplete": 0, "ignored": 0, "repeated": 0}


def test_missing_bones_complete_from_last_pose_and_incomplete_start_is_dropped():
    frames = vmc.VmcEncoder()(random_motion(2))
    asm = vmc.VmcFrameAssembler()
    partial = vmc.VmcFrame({b: v for b, v in frames[0].bones.items() if b != "LeftHand"})
    assert asm.feed_datagram(vmc.frame_bundle(partial, 0.0).dgram) == []
    # The next frame's first message ends it, and a hand is still unknown: counted, not sent.
    assert len(asm.feed_datagram(vmc.frame_bundle(frames[0], 0.1).dgram)) == 1
    assert asm.counts["incomplete"] == 1
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
    assert asm.feed_datagram(message("/not/vmc", 1.0)) == []
    assert asm.feed_datagram(message(vmc.BONE_ADDRESS, "Tail", *[0.0] * 6, 1.0)) == []
    assert asm.feed_datagram(message(vmc.BLEND_ADDRESS, "Joy", float("nan"))) == []
    assert asm.counts["malformed"] == len(GARBAGE) + 1
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


# --- frames however the sender bundles them ------------------------------------------------------

def _messages(frame, time):
    """A frame's messages in a performer's order (root, bones, blendshapes, Apply, OK, T)."""
    from pythonosc import osc_packet

    return [m.message for m in osc_packet.OscPacket(vmc.frame_bundle(frame, time).dgram).messages]


def _bundle(messages):
    return vmc.bundle(messages).dgram


def _styles(frames):
    """Datagrams per bundling style of the same frames."""
    per_frame = [_messages(f, k / 60) for k, f in enumerate(frames)]
    t_first = [m[-1:] + m[:-1] for m in per_frame]
    no_time = [[x for x in m if x.address != vmc.TIME_ADDRESS] for m in per_frame]
    return {
        "one bundle per frame": [_bundle(m) for m in per_frame],
        "message per bundle": [_bundle([x]) for m in per_frame for x in m],
        "loose messages": [x.dgram for m in per_frame for x in m],
        "three bundles per frame": [_bundle(m[i::3]) for m in per_frame for i in range(3)],
        "time first, message per bundle": [_bundle([x]) for m in t_first for x in m],
        "no time, message per bundle": [_bundle([x]) for m in no_time for x in m],
    }


def _assert_frames_are_the_poses(got, frames):
    assert len(got) == len(frames)  # one frame per pose: no multiplied rate, none lost
    for g, f in zip(got, frames):  # and no mixed poses: every bone of each frame is that pose's
        for b, (p, q) in f.bones.items():
            np.testing.assert_array_equal(g.bones[b][0], p)
            np.testing.assert_allclose(g.bones[b][1], q, atol=1e-7)
        assert g.blendshapes == f.blendshapes


@pytest.fixture(scope="module")
def humanoid():
    return unity_humanoid()


@pytest.fixture(scope="module")
def sent(humanoid):
    """A sender's frames on an A-pose rig of other proportions: body, fingers, blendshapes."""
    return sender_frames(random_motion(12, spread=0.3), humanoid)


@pytest.mark.parametrize("style", ["one bundle per frame", "message per bundle", "loose messages",
                                   "three bundles per frame", "time first, message per bundle",
                                   "no time, message per bundle"])
def test_a_frame_is_a_whole_pose_however_the_sender_bundles_it(sent, style):
    datagrams = _styles(sent)[style]
    asm = vmc.VmcFrameAssembler()
    got = [f for d in datagrams for f in asm.feed_datagram(d)]
    if style.startswith("no time") or style == "loose messages" and len(got) < len(sent):
        # Without a bundle holding a whole frame, the first frame ends with the second one's first
        # message; the last one ends at the learnt last key.
        pass
    _assert_frames_are_the_poses(got, sent)
    assert asm.counts["malformed"] == asm.counts["incomplete"] == 0


def test_a_lost_datagram_neither_mixes_poses_nor_unlearns_the_pattern(sent):
    per_frame = [_messages(f, k / 60) for k, f in enumerate(sent)]
    lost_time = per_frame[4][-1]  # the learnt last key of frame 4
    lost_bone = next(m for m in per_frame[7] if m.params and m.params[0] == "LeftLowerArm")
    datagrams = [_bundle([x]) for m in per_frame for x in m if x is not lost_time and x is not lost_bone]
    asm = vmc.VmcFrameAssembler()
    got = [f for d in datagrams for f in asm.feed_datagram(d)]
    expected = list(sent)
    # Frame 7 lacks its LeftLowerArm: completed from frame 6's (the last known one).
    expected[7] = vmc.VmcFrame({**sent[7].bones, "LeftLowerArm": sent[6].bones["LeftLowerArm"]},
                               blendshapes=sent[7].blendshapes)
    _assert_frames_are_the_poses(got, expected)
    assert asm.last_key == ("time",)
    assert [f.time for f in got[3:7]] == pytest.approx([3 / 60, 3 / 60, 5 / 60, 6 / 60])


# --- the bridge's link: in, and back out on the sender's rig -----------------------------------

def _link_round_trip(frames, delay_frames=0, period_ns=16_666_667):
    """Frames through VmcLink.receive, the JointState values straight back through send (what the
    relay node does; with ``delay_frames``, a stylizer that changes nothing): the frames a
    marionette then receives, and the JointStates."""
    link = VmcLink()
    asm = vmc.VmcFrameAssembler()
    received, states = [], []
    for k, f in enumerate(asm.feed_datagram(vmc.frame_bundle(f, k / 60).dgram)[0]
                          for k, f in enumerate(frames)):
        names, values = link.receive(f, 10**9 + k * period_ns)
        states.append((names, values))
        # What a stylizer with that latency sends back: its pass-through names are the shown frame's.
        back = values.copy()
        n_body = len(link.layout.names)
        back[n_body:] = states[max(0, k - delay_frames)][1][n_body:]
        bundle = link.send(names, back, 10**9 + k * period_ns, delay_frames * period_ns, k / 60)
        received += vmc.VmcFrameAssembler().feed_datagram(bundle.dgram)
    return received, states, link


def _assert_bones_as_sent(got, frame, deg=1e-4, metres=1e-6):
    assert set(got.bones) == set(frame.bones)  # every bone the sender sent, UpperChest included
    for b, (p, q) in frame.bones.items():
        err = np.degrees(rot.angle_between(vmc.unity_to_core_rotation(q),
                                           vmc.unity_to_core_rotation(got.bones[b][1])))
        assert err < deg, (b, err)
        np.testing.assert_allclose(got.bones[b][0], p, atol=metres, err_msg=b)


def test_link_returns_every_bone_of_the_sender_rig_as_it_came(humanoid):
    # An A-pose rig with toes below the ankles, an UpperChest, other proportions, and a v2.1 root
    # with a turn, a scale and an offset: a relay in the stylizer's place gives it all back.
    root = (np.array([0.4, 0.1, -0.3]), Rotation.from_euler("y", 35, degrees=True).as_quat(),
            np.array([1.25, 1.25, 1.25]), np.array([0.1, 0.0, 0.2]))
    frames = sender_frames(random_motion(6, spread=0.3), humanoid, root=root)
    got, states, _ = _link_round_trip(frames)
    for g, f in zip(got, frames):
        _assert_bones_as_sent(g, f)
        np.testing.assert_array_equal(g.root[0], f.root[0])
        np.testing.assert_array_equal(g.root_scale, f.root_scale)
        np.testing.assert_array_equal(g.root_offset, f.root_offset)
        assert g.blendshapes == f.blendshapes and g.apply and g.ok == f.ok
    # Fingers, eyes and jaw travel in the JointState as names of their own, the sender's rotations.
    names, values = states[2]
    extra = [n for n in names if n.startswith("LeftIndexProximal_")]
    assert extra == ["LeftIndexProximal_rx", "LeftIndexProximal_ry", "LeftIndexProximal_rz"]
    q = rotations_from_values(values[[names.index(n) for n in extra]])
    expected = vmc.unity_to_core_rotation(frames[2].bones["LeftIndexProximal"][1])
    assert np.degrees(rot.angle_between(q[0], expected)) < 1e-6


def test_link_sends_fingers_and_blendshapes_bit_for_bit_with_the_frame_the_pose_shows(sent):
    # One frame of latency: the output stamped k shows frame k - 1, and so do its extras.
    got, _, link = _link_round_trip(sent, delay_frames=1)
    for k in range(1, len(sent)):
        shown = sent[k - 1]
        for b in vmc.EXTRA_BONES:
            assert got[k].bones[b][1].tolist() == shown.bones[b][1].tolist()
        assert got[k].blendshapes == shown.blendshapes
    assert got[0].blendshapes == sent[0].blendshapes  # nothing older yet: the nearest frame


def test_link_time_is_what_the_bridge_gives_and_advances(sent):
    got, _, _ = _link_round_trip(sent)
    times = [g.time for g in got]
    assert times == pytest.approx([k / 60 for k in range(len(sent))], abs=1e-6)
    assert np.all(np.diff(times) > 0)


def test_a_stylized_pose_goes_out_on_the_sender_rig(humanoid, sent):
    """A stylized canonical pose (here: every arm lowered and the root moved) arrives on the
    sender's rig: its bone directions are the canonical ones, its bone lengths the sender's."""
    link = VmcLink()
    names, values = link.receive(sent[0], 10**9)
    rotations, root = link.layout.decode(names, values)
    turn = rot.from_axis_angle(np.array([0.0, 0.0, 1.0]), np.radians(25.0))
    rotations = rotations.copy()
    for j in (canonical().index("UpperArm_L"), canonical().index("UpperArm_R")):
        rotations[j] = rot.multiply(rotations[j], turn)
    root = root + np.array([0.1, 0.0, 0.05])
    styled = link.layout.encode(rotations, root)
    values = values.copy()
    values[: len(styled)] = styled
    (out,) = vmc.VmcFrameAssembler().feed_datagram(link.send(names, values, 10**9, 0, 0.0).dgram)
    target = Motion.from_rotations(canonical(), rotations[None], root[None], 30.0)
    back = vmc.VmcDecoder()([out])
    from motion_style_ros.core.retarget import bone_direction_errors

    _, err = bone_direction_errors(target, back)
    assert err.max() < 0.01
    np.testing.assert_allclose(back.root_positions, target.root_positions, atol=1e-5)
    for b in ("LeftLowerArm", "LeftToes", "Chest", "UpperChest"):  # the sender's own bone offsets
        np.testing.assert_array_equal(out.bones[b][0], sent[0].bones[b][0])
    # The arm did turn: the output is not the frame that came in.
    assert np.degrees(rot.angle_between(vmc.unity_to_core_rotation(out.bones["LeftUpperArm"][1]),
                                        vmc.unity_to_core_rotation(sent[0].bones["LeftUpperArm"][1]))) > 5


def test_root_offset_is_taken_off_and_the_scale_cancels(humanoid):
    m = random_motion(3, spread=0.3)
    plain = sender_frames(m, humanoid)
    offset = (np.array([1.5, 0.2, -0.7]), np.array([0.0, 0.0, 0.0, 1.0]), np.array([2.0, 2.0, 2.0]),
              np.array([1.5, 0.2, -0.7]))
    shifted = sender_frames(m, humanoid, root=offset)  # the avatar placed at p - offset: the same
    a, b = vmc.VmcDecoder()(plain), vmc.VmcDecoder()(shifted)
    assert_same_motion(a, b, deg=1e-4, metres=1e-5)


def test_ok_states_that_say_the_pose_is_not_the_performers_are_counted(sent):
    link = VmcLink()
    with_ok = [dict(ok=(0,)), dict(ok=(1, 1, 0)), dict(ok=(1, 2, 0)), dict(ok=(1, 3, 0, 0))]
    for k, ok in enumerate(with_ok):
        frame = vmc.VmcFrame(sent[k].bones, **ok)
        assert link.receive(frame, 10**9 + k) is None
    assert link.counts == {"not_loaded": 1, "calibrating": 2, "tracking_lost": 1}
    assert link.receive(vmc.VmcFrame(sent[0].bones, ok=(1, 0, 0)), 2 * 10**9) is not None  # uncalibrated
    rig = link.decoder.rig
    assert link.receive(vmc.VmcFrame(sent[1].bones, ok=(1, 3, 0, 1)), 3 * 10**9) is not None
    assert link.decoder.rig is not rig  # a calibration finished: the rig is built anew


def test_a_unity_rig_with_other_proportions_and_an_a_pose_rest_is_stylized_as_a_canonical_one(
        datasets, humanoid):
    from motion_style_ros.io.datasets import index_bandai, load_clip
    from motion_style_ros.runtime.recurrent import RecurrentSession

    info = next(i for i in index_bandai(datasets) if i.content == "walk")
    clip = load_clip(info)[:90]
    decoded = vmc.VmcDecoder(fps=clip.fps)(sender_frames(clip, humanoid))
    # The stream decodes to the clip itself: rest pose and proportions are the sender's business.
    assert_same_motion(decoded, clip, deg=0.01, metres=1e-4)
    session = RecurrentSession(input_fps=clip.fps)
    a = session.run(clip, "elderly")
    b = session.run(decoded, "elderly")
    err = np.degrees(rot.angle_between(a.rotations[:, 1:], b.rotations[:, 1:]))
    assert err.max() < 0.05, err.max()
    np.testing.assert_allclose(a.global_positions(), b.global_positions(), atol=1e-3)


# --- time and the receiver ---------------------------------------------------------------------

def test_sender_clock_keeps_the_senders_rhythm_and_falls_back_on_arrival():
    clock = vmc.SenderClock(tolerance=0.1)
    base = 5 * 10**9
    # Bunched by the network, the first frame the most delayed: the stamps keep the sender's
    # 60 Hz spacing once the offset has come down to the least delayed arrival.
    arrivals = [30_000_000, 21_000_000, 33_500_000, 52_000_000, 67_000_000, 83_700_000, 110_000_000]
    stamps = np.array([clock.stamp(k / 60, base + a) for k, a in enumerate(arrivals)])
    assert np.all(np.diff(stamps) >= 8_333_333)  # always forwards, at least half a frame a step
    np.testing.assert_allclose(np.diff(stamps)[-2:], 1e9 / 60, atol=50_000)  # creeping 1000 ppm
    assert stamps[-1] <= base + arrivals[-1]  # never later than arrival once settled
    epoch = float(np.float32(1796169856.0))  # an epoch time as float32: it does not advance
    assert clock.stamp(epoch, 6 * 10**9) == 6 * 10**9
    assert clock.stamp(epoch, 6 * 10**9 + 16_000_000) == 6 * 10**9 + 16_000_000
    assert clock.stamp(None, 7 * 10**9) == 7 * 10**9
    # A sender restarted (its time back near 0): arrival time, then its rhythm again.
    assert clock.stamp(0.5, 8 * 10**9) == 8 * 10**9
    assert abs(clock.stamp(0.5 + 1 / 60, 8 * 10**9 + 19_000_000) - (8 * 10**9 + 16_666_667)) < 50_000
    # Held up for 200 ms, then catching up: the frames keep the sender's rhythm (to the 1000 ppm
    # the offset may creep up by over the time that passed).
    base = 8 * 10**9

    def arrival(k):
        return k * 16_666_667 if k < 6 else max(300_000_000 + (k - 6) * 4_000_000, k * 16_666_667)

    held = [clock.stamp(0.5 + k / 60, base + arrival(k)) for k in range(2, 30)]
    np.testing.assert_allclose(np.diff(held), 1e9 / 60, atol=500_000)
    # A sender that fell 0.6 s behind and stays behind: the stamps catch up at 10 % (each step at
    # most 1.1 frames long, never a gap) until they trail arrival by less than the tolerance.
    late = np.array([clock.stamp(1.0 + k / 60, base + 1_100_000_000 + k * 16_666_667) for k in range(400)])
    assert np.all(np.diff(late) >= 16_666_000) and np.all(np.diff(late) <= 1.1 * 16_666_667 + 1000)
    assert 0 <= base + 1_100_000_000 + 399 * 16_666_667 - late[-1] <= 100_000_000
    # The sender that was behind catches up (its frames arrive 0.4 s earlier against their time than
    # the clock had come to follow): slewed down, never a step shorter than half a frame.
    t0, a0 = 1.0 + 400 / 60, base + 1_100_000_000 + 400 * 16_666_667 - 400_000_000
    caught = np.array([clock.stamp(t0 + k / 60, a0 + k * 16_666_667) for k in range(120)])
    assert np.all(np.diff(caught) >= 8_333_000)
    assert caught[-1] <= a0 + 119 * 16_666_667
    # A time that jumps ahead: anchored at arrival at once; never backwards.
    assert clock.stamp(50.0, base + 12 * 10**9) == base + 12 * 10**9
    assert clock.stamp(60.0, base) == base + 12 * 10**9 + 1


@pytest.mark.parametrize("max_age", [60.0, vmc.MAX_AGE_S])
def test_a_burst_of_datagrams_is_read_without_kernel_drops(sent, max_age):
    """One second of a message-per-bundle sender at 60 Hz (about 110 datagrams a frame) sent at
    once, while the frame callback takes its time: every datagram is read. With time to spare
    every frame is made; at the live bound, what waited too long is dropped (counted), what is
    made is whole poses of the stream in order, and the frame sent after the burst is shown."""
    import time

    frames = (sent * 6)[:61]
    datagrams = [[_bundle([x]) for x in _messages(f, k / 60)] for k, f in enumerate(frames)]
    got = []
    receiver = vmc.VmcReceiver(lambda f: (got.append(f), time.sleep(0.002)), port=0, max_age=max_age).start()

    def quiet():
        before = -1
        while before != (now := (len(got), receiver.counts["stale"], receiver.counts["superseded"])):
            before = now
            time.sleep(0.3)

    try:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as raw:
            for d in sum(datagrams[:60], []):
                raw.sendto(d, receiver.address)
            quiet()
            burst = len(got)
            for d in datagrams[60]:  # the sender's next frame, in its time
                raw.sendto(d, receiver.address)
            quiet()
    finally:
        receiver.close()
    counts = receiver.counts
    assert counts["kernel_dropped"] == counts["overflow"] == 0
    assert counts["datagrams"] == sum(map(len, datagrams))
    if max_age > 1:
        assert len(got) == len(frames) and counts["stale"] == counts["superseded"] == 0
        return
    assert (burst < 60) == (counts["stale"] + counts["superseded"] > 0), (burst, counts)
    times = [round(f.time * 60) for f in got]
    assert times == sorted(times) and times[-1] == 60  # the frame after the burst is shown
    for g, k in zip(got, times):  # whole poses only: never one mixing frames from before and after a drop
        assert all(np.array_equal(g.bones[b][0], p) for b, (p, _) in frames[k].bones.items()), k


def test_fuzzed_streams_through_the_link_never_give_nan(sent):
    """Corrupted datagrams of a full sender stream: whatever frames the assembler still makes
    either convert to finite values or are refused with a reason, and what goes out is finite."""
    good = [vmc.frame_bundle(f, k / 60).dgram for k, f in enumerate(sent)]
    asm, link = vmc.VmcFrameAssembler(), VmcLink()
    converted = refused = 0
    for k in range(200):
        data = np.frombuffer(good[k % len(good)], dtype=np.uint8).copy()
        if k % 3:
            data[RNG.integers(0, len(data), 4)] = RNG.integers(0, 256, 4)
        for frame in asm.feed_datagram(data.tobytes()):
            try:
                out = link.receive(frame, 10**9 + k * 16_666_667)
            except MotionStyleError:
                refused += 1
                continue
            if out is None:  # an OK state that says so
                continue
            names, values = out
            assert np.isfinite(values).all()
            converted += 1
            (back,) = vmc.VmcFrameAssembler().feed_datagram(
                link.send(names, values, 10**9 + k * 16_666_667, 0, k / 60).dgram)
            assert all(np.isfinite(p).all() and np.isfinite(q).all() for p, q in back.bones.values())
    assert converted > 50 and asm.counts["malformed"] > 0
    with pytest.raises(MotionStyleError, match="non-finite"):
        link.send(names, np.full(len(names), np.nan), 10**9, 0, 0.0)


def test_the_rig_is_kept_while_the_avatar_stays_and_built_anew_for_another(humanoid, sent):
    decoder = vmc.VmcDecoder()
    decoder(sent[:1])
    rig = decoder.rig
    for f in sent[1:]:  # the hips move (root motion): the same avatar
        decoder([f])
    assert decoder.rig is rig
    other = sender_frames(random_motion(2, spread=0.3), unity_humanoid(arm=0.9, leg=1.1))
    decoder(other[:1])
    assert decoder.rig is not rig
    assert not np.allclose(decoder.rig.offsets[1:], rig.offsets[1:])


def test_blendshapes_in_a_bundle_after_the_pose_are_learnt_as_that_frames(sent):
    """A sender that bundles the whole body with OK and T, then the blendshapes in a bundle of their
    own: after two frames of learning the blendshapes go with the pose they were sent after."""
    datagrams = []
    for k, f in enumerate(sent):
        m = _messages(f, k / 60)
        blend = [x for x in m if x.address in (vmc.BLEND_ADDRESS, vmc.APPLY_ADDRESS)]
        datagrams += [_bundle([x for x in m if x not in blend]), _bundle(blend)]
    asm = vmc.VmcFrameAssembler()
    got = [f for d in datagrams for f in asm.feed_datagram(d)]
    assert asm.last_key == ("apply",)
    assert len(got) == len(sent)  # one frame per pose: a tail is never a frame of its own
    for g, f in zip(got[3:], sent[3:]):
        assert g.blendshapes == f.blendshapes
        np.testing.assert_array_equal(g.bones["LeftHand"][0], f.bones["LeftHand"][0])
        np.testing.assert_allclose(g.bones["LeftHand"][1], f.bones["LeftHand"][1], atol=1e-7)


def test_a_finger_changed_on_its_way_back_goes_out_as_it_came_back(sent):
    link = VmcLink()
    (frame,) = vmc.VmcFrameAssembler().feed_datagram(vmc.frame_bundle(sent[0], 0.0).dgram)
    names, values = link.receive(frame, 10**9)
    changed = values.copy()
    i = names.index("LeftIndexProximal_rz")
    changed[i] += 0.3  # a node between bent one finger joint
    (out,) = vmc.VmcFrameAssembler().feed_datagram(link.send(names, changed, 10**9, 0, 0.0).dgram)
    want = rotations_from_values(changed[i - 2: i + 1])[0]
    got = vmc.unity_to_core_rotation(out.bones["LeftIndexProximal"][1])
    assert np.degrees(rot.angle_between(want, got)) < 1e-4
    np.testing.assert_array_equal(out.bones["LeftIndexProximal"][0], sent[0].bones["LeftIndexProximal"][0])
    for b in vmc.EXTRA_BONES:  # the others bit for bit
        if b != "LeftIndexProximal":
            assert out.raw[b].dgram == frame.raw[b].dgram


def test_bone_messages_and_bundles_are_encoded_as_python_osc_encodes_them():
    from pythonosc import osc_bundle_builder, osc_packet

    p, q = np.array([0.1, -0.25, 3.0]), np.array([0.0, 0.6, 0.0, 0.8])
    for name in ("Hips", "LeftThumbIntermediate", "Neck"):  # names padded to 4 bytes differently
        assert vmc.bone_message(name, p, q).dgram == vmc.build_message(
            vmc.BONE_ADDRESS, [name, *map(float, p), *map(float, q)]).dgram
    messages = [vmc.bone_message("Hips", p, q), vmc.build_message(vmc.TIME_ADDRESS, [1.5])]
    builder = osc_bundle_builder.OscBundleBuilder(osc_bundle_builder.IMMEDIATELY)
    for m in messages:
        builder.add_content(vmc.build_message(*(lambda x: (x.address, x.params))(
            osc_packet.OscPacket(m.dgram).messages[0].message)))
    assert vmc.bundle(messages).dgram == builder.build().dgram


def test_one_datagram_of_one_bone_700_times_is_no_more_than_one_frame(sent):
    """A key twice in one datagram is no sender's frame: the repeats are dropped and counted."""
    asm = vmc.VmcFrameAssembler()
    assert len(asm.feed_datagram(vmc.frame_bundle(sent[0], 0.0).dgram)) == 1
    hand = [m for m in _messages(sent[1], 1 / 60) if m.params and m.params[0] == "LeftHand"]
    got = asm.feed_datagram(_bundle(hand * 700))
    got += asm.feed_datagram(vmc.frame_bundle(sent[2], 2 / 60).dgram)
    assert len(got) <= 2 and asm.counts["repeated"] == 699
    np.testing.assert_array_equal(got[-1].bones["Hips"][0], sent[2].bones["Hips"][0])


def test_garbage_makes_the_assembler_learn_the_senders_pattern_again(sent):
    per_frame = [_messages(f, k / 60) for k, f in enumerate(sent)]
    asm = vmc.VmcFrameAssembler()
    for m in per_frame[:3]:
        for x in m:
            asm.feed_datagram(_bundle([x]))
    assert asm.last_key == ("time",)
    asm.feed_datagram(b"\x00garbage")
    assert asm.last_key is None and asm.first_key is None and asm.counts["malformed"] == 1
    got = [f for m in per_frame[3:] for x in m for f in asm.feed_datagram(_bundle([x]))]
    assert asm.last_key == ("time",)  # learnt again from the stream
    _assert_frames_are_the_poses(got, sent[3:])
