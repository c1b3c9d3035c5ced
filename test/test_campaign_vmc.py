"""The bad-input campaign against a real vmc_bridge process (issue 18), over real UDP and DDS: every
kind of bad VMC/OSC datagram, and every kind of bad stylized JointState on the way back out, sent
between good frames. The bridge never exits, never publishes a non-finite value, counts each bad
item in its diagnostics under its reason, and the good frame right after each comes out right."""

import struct

import numpy as np
from pythonosc.osc_message_builder import OscMessageBuilder
from ros_helpers import BEST_EFFORT, TIMEOUT, message
from sensor_msgs.msg import JointState
from test_vmc import message as osc
from test_vmc_bridge import LAYOUT, assert_pose, bridge, decoded, vmc_out  # noqa: F401 (fixtures)

from motion_style_ros.core.synthetic import synthetic_motion
from motion_style_ros.io import vmc

MOTION = synthetic_motion("walk", 30.0, 6.0)
FRAMES = vmc.VmcEncoder()(MOTION)
REASONS = ("malformed", "ignored", "incomplete", "conversion_errors", "not_loaded", "not_sent")
FLOOD = 100  # datagrams of one bone
T0 = 1_700_000_000 * 10**9
PERIOD = 33_333_333


def blend(k):
    """The good frames' one blendshape value (a float32, as OSC carries it)."""
    return float(np.float32((k % 10) / 10))


def frame(k, **changes):
    """Frame ``k`` as a sender sends it (with a blendshape), ``changes`` replacing its fields."""
    fields = {"bones": FRAMES[k].bones, "blendshapes": {"Joy": blend(k)}, "apply": True, "ok": (1,)}
    return vmc.VmcFrame(**{**fields, **changes})


def bundle(f, k, timetag=None):
    """``f`` as one bundle whose /VMC/Ext/T is frame ``k``'s time; ``timetag`` replaces "now"."""
    data = vmc.frame_bundle(f, k / MOTION.fps).dgram
    return data if timetag is None else data[:8] + timetag + data[16:]


def typed(address, tags, *args):
    """An OSC message with its type tags given (python-osc never picks doubles, ``d``, itself)."""
    builder = OscMessageBuilder(address)
    for tag, arg in zip(tags, args):
        builder.add_arg(arg, tag)
    return builder.build().dgram


def bone(name, p=(0.0, 0.0, 0.0), q=(0.0, 0.0, 0.0, 1.0)):
    return osc(vmc.BONE_ADDRESS, name, *map(float, p), *map(float, q))


def bad_inputs(k):
    """(kind, datagrams, counts they add, poses the bridge must publish for them) per kind, made
    from frame ``k``; the good frame ``k + 1`` follows each."""
    good = bundle(frame(k), k)
    size = 16 + 4  # the first element's contents start here
    nested = osc("/VMC/Ext/T", 1.0)
    for _ in range(2000):  # python-osc recursed until RecursionError
        nested = b"#bundle\x00" + bytes(8) + struct.pack(">i", len(nested)) + nested
    scaled = {b: (p, 1e3 * q) for b, (p, q) in FRAMES[k].bones.items()}
    flat = {b: (np.zeros(3), q) for b, (_, q) in FRAMES[k].bones.items()}
    flood = [bone("LeftHand", q=(0.0, 0.0, np.sin(i / 10), np.cos(i / 10))) for i in range(FLOOD)]
    malformed = {"malformed": 1}
    return [
        ("random bytes", [bytes(np.random.default_rng(k).integers(0, 256, 300, dtype=np.uint8))],
         malformed, []),
        ("empty datagram", [b""], malformed, []),
        ("text, not OSC", [b"hello VMC"], malformed, []),
        ("truncated bundle", [good[:-13]], malformed, []),
        ("element size past the end", [good[:16] + struct.pack(">i", 10**6) + good[size:]],
         malformed, []),
        ("negative element size", [good[:16] + struct.pack(">i", -4) + good[size:]], malformed, []),
        ("bundles nested 2000 deep", [nested], malformed, []),
        ("unknown type tag", [osc(vmc.BONE_ADDRESS, "Hips").replace(b",s", b",X")], malformed, []),
        ("string not UTF-8", [b"/VMC/Ext/Bone/Pos\x00\x00\x00,s\x00\x00\xff\xfe\x00\x00"], malformed, []),
        ("bone: a string among the numbers", [osc(vmc.BONE_ADDRESS, "Hips", "x", *[0.0] * 5, 1.0)],
         malformed, []),
        ("bone: too few arguments", [osc(vmc.BONE_ADDRESS, "Hips", 1.0, 2.0)], malformed, []),
        ("bone: too many arguments", [osc(vmc.BONE_ADDRESS, "Hips", *[0.0] * 6, 1.0, 5.0)],
         malformed, []),
        ("bone: name an OSC array", [osc(vmc.BONE_ADDRESS, ["Hips"], *[0.0] * 6, 1.0)], malformed, []),
        ("bone: NaN position", [bone("Hips", p=(np.nan, 0.0, 0.0))], malformed, []),
        ("bone: Inf rotation", [bone("LeftHand", q=(np.inf, 0.0, 0.0, 1.0))], malformed, []),
        ("bone: hips at 1e30", [bone("Hips", p=(1e30, 1e30, 1e30))], malformed, []),
        ("bone: offset of 1e30", [bone("LeftLowerArm", p=(1e30, 0.0, 0.0))], malformed, []),
        ("bone: zero quaternion", [bone("Hips", p=(0.0, 1.0, 0.0), q=(0.0, 0.0, 0.0, 0.0))],
         malformed, []),
        ("bone: quaternion of 1e200 (doubles)",
         [typed(vmc.BONE_ADDRESS, "sddddddd", "LeftHand", 0.0, 0.0, 0.0, 1e200, 0.0, 0.0, 1e200)],
         malformed, []),
        ("root: NaN", [osc(vmc.ROOT_ADDRESS, "root", *[float("nan")] * 7)], malformed, []),
        ("root: at 1e30", [osc(vmc.ROOT_ADDRESS, "root", 1e30, 1e30, 1e30, 0.0, 0.0, 0.0, 1.0)],
         malformed, []),
        ("root: zero scale", [osc(vmc.ROOT_ADDRESS, "root", *[0.0] * 6, 1.0, *[0.0] * 6)], malformed, []),
        ("OK: a float, a string, five integers",
         [osc(vmc.OK_ADDRESS, 1.0), osc(vmc.OK_ADDRESS, "yes"), osc(vmc.OK_ADDRESS, 1, 3, 0, 1, 9)],
         {"malformed": 3}, []),
        ("T: a string, NaN, 1e300 (a double), -1e30",
         [osc(vmc.TIME_ADDRESS, "now"), osc(vmc.TIME_ADDRESS, float("nan")),
          typed(vmc.TIME_ADDRESS, "d", 1e300), osc(vmc.TIME_ADDRESS, -1e30)], {"malformed": 4}, []),
        ("blendshape: NaN, 1e30, no value, a number for a name",
         [osc(vmc.BLEND_ADDRESS, "Joy", float("nan")), osc(vmc.BLEND_ADDRESS, "Joy", 1e30),
          osc(vmc.BLEND_ADDRESS, "Joy"), osc(vmc.BLEND_ADDRESS, 3, 1.0)], {"malformed": 4}, []),
        ("unknown bone name", [bone("Tail")], {"ignored": 1}, []),
        ("unknown address", [osc("/not/vmc", "Joy", 1.0)], {"ignored": 1}, []),
        ("oversized datagram (a 60 kB bone name)", [bone("x" * 60_000)], {"ignored": 1}, []),
        ("a frame whose OK says no avatar", [bundle(frame(k, ok=(0,)), k)], {"not_loaded": 1}, []),
        ("a frame no rig can be built from", [bundle(frame(k, bones=flat), k)],
         {"conversion_errors": 1}, []),
        ("a frame of quaternions 1000 long", [bundle(frame(k, bones=scaled), k)], {}, [k]),
        ("a frame with a far-future time tag", [bundle(frame(k), k, timetag=b"\xff" * 8)], {}, [k]),
        # A frame each while the bridge keeps up (the sender's pattern); what waits longer than
        # the receiver's live bound gives way to the newest (io.vmc.VmcReceiver).
        ("a flood of one bone", flood, {}, [None]),
    ]


def test_no_bad_datagram_stops_or_poisons_the_stream(bridge):
    got, blends = [], []  # deep queues: a flood of one bone may come out as a flood of states
    bridge.node.create_subscription(JointState, "joint_states", got.append, BEST_EFFORT)
    bridge.node.create_subscription(JointState, "blendshapes", blends.append, BEST_EFFORT)
    bridge.exchange(lambda: bridge.sender.send_packet(vmc.Packet(bundle(frame(0), 0))), got, "frame 0")
    n_kinds = len(bad_inputs(1))
    expected = dict.fromkeys(REASONS, 0)
    k = 1
    for i in range(n_kinds):
        kind, datagrams, counts, poses = bad_inputs(k)[i]
        n = len(got)
        for data in datagrams:
            bridge.sender.send_packet(vmc.Packet(data))
        assert bridge.spin_until(lambda: len(got) >= n + len(poses), kind), f"{kind}: {len(got) - n} states"
        if None in poses:  # the flood's own states (the sender's pattern): let the last ones in
            bridge.spin_until(lambda: False, "the rest of the flood", timeout=1.0)
        for state, pose in zip(got[n:], poses):
            if pose is not None:
                assert_pose(*decoded(state), MOTION, pose)
        for reason, count in counts.items():
            expected[reason] += count
        n = len(got)
        bridge.sender.send(frame(k + 1), (k + 1) / MOTION.fps)
        assert bridge.spin_until(lambda: len(got) > n, kind), f"no state for the good frame after {kind}"
        assert_pose(*decoded(got[n]), MOTION, k + 1)  # the first state after it, and right
        k += 2

    assert bridge.spin_until(lambda: bridge.diagnostics and all(
        bridge.counters().get(r, 0) >= c for r, c in expected.items()), "the counts")
    bridge.spin_until(lambda: False, "any later count", timeout=1.5)
    counted = {r: int(bridge.counters().get(r, 0)) for r in REASONS}
    assert counted == expected
    assert bridge.counters()["frames"] >= len(got) and bridge.proc.poll() is None
    assert np.isfinite([p for s in got + blends for p in s.position]).all()
    # Every blendshape published is a good frame's (1e30 was published before).
    assert {p for s in blends for p in s.position} <= {blend(j) for j in range(k)} and blends
    print(f"{n_kinds} kinds of bad VMC input, counted {counted}")


def test_no_bad_stylized_state_stops_the_stream_back_out(bridge, vmc_out):
    values = LAYOUT.encode_motion(MOTION)
    names = LAYOUT.names
    bridge.exchange(lambda: bridge.sender.send_packet(vmc.Packet(bundle(frame(0), 0))), bridge.states,
                    "the sender's frame")  # kept: what goes back out is on this sender's rig

    def with_(t, index, value):
        v = values[t].copy()
        v[index] = value
        return v

    bad = [
        ("one position short", lambda t: message(T0, names, values[t][:-1])),
        ("one position too many", lambda t: message(T0, names, np.append(values[t], 0.0))),
        ("no names, no positions", lambda t: message(T0, [], [])),
        ("NaN", lambda t: message(T0, names, with_(t, 7, np.nan))),
        ("Inf", lambda t: message(T0, names, with_(t, 0, np.inf))),
        ("root at 1e30", lambda t: message(T0, names, with_(t, slice(0, 3), 1e30))),
        ("root at 1e39, beyond float32", lambda t: message(T0, names, with_(t, slice(0, 3), 1e39))),
        ("every value the largest float", lambda t: message(T0, names, np.full(len(names), 1.7e308))),
        ("an angle of 1e6 rad", lambda t: message(T0, names, with_(t, 10, 1e6))),
        ("a name twice", lambda t: message(T0, [names[0]] + names[:-1], values[t])),
        ("names in lower case", lambda t: message(T0, [n.lower() for n in names], values[t])),
    ]
    back = []
    for t, (kind, make) in enumerate(bad):
        n = len(vmc_out.frames)
        bridge.stylized.publish(make(t))
        bridge.exchange(lambda t=t: bridge.stylized.publish(message(T0 + t * PERIOD, names, values[t])),
                        vmc_out.frames, f"the good state after {kind}")
        back.append(vmc_out.frames[n])  # the first frame out after the bad state: the good one's
    motion = vmc.VmcDecoder(fps=MOTION.fps)(back)
    for t in range(len(bad)):
        assert_pose(motion.rotations[t], motion.root_positions[t], MOTION, t)
    assert bridge.spin_until(lambda: bridge.diagnostics and bridge.counters()["not_sent"] >= len(bad),
                             "the not_sent count", timeout=TIMEOUT / 4)
    assert bridge.counters()["not_sent"] == len(bad) and bridge.proc.poll() is None
    assert vmc_out.counts["malformed"] == 0  # nothing non-finite went out
    assert all(np.isfinite(p).all() and np.isfinite(q).all() for f in back for p, q in f.bones.values())
