"""VMC end to end over real UDP, against a VMC implementation nobody here wrote: vmcp 1.0.6 (osc4py3
backend) sends a 60 Hz clip with finger bones and blendshapes -> vmc_bridge -> relay or stylizer ->
vmc_bridge out -> vmcp receives. Real nodes in their own processes over DDS (reliable QoS).

The sender bundles each frame once (one ``send()`` per frame) or sends every message as its own
bundle (one ``send()`` per message). Checked: one output frame per pose sent, none lost; with the
relay in the stylizer's place every bone (feet, spine, UpperChest, root) comes back as sent; fingers,
eyes, jaw and blendshapes arrive exactly as sent (float32) with the frame the output's pose shows;
the kernel dropped no datagram. ``VMC_E2E_SECONDS`` sets the length (5 s by default; the README's
figures come from 30 s); ``-s`` prints what each run measured.
"""

import json
import os
import socket
import time
import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.qos import QoSProfile, ReliabilityPolicy

from motion_style_ros.core import rotations as rot
from motion_style_ros.core.synthetic import synthetic_motion
from motion_style_ros.io import vmc
from vmc_helpers import BLENDSHAPES, sender_frames, unity_humanoid

vmcp = pytest.importorskip("vmcp", reason="vmcp (requirements-test.txt) is the VMC peer of these tests")
from vmcp.events import (  # noqa: E402
    BlendShapeEvent,
    BoneTransformEvent,
    RelativeTimeEvent,
    RootTransformEvent,
    StateEvent,
)
from vmcp.facades import on_receive  # noqa: E402
from vmcp.osc import OSC  # noqa: E402
from vmcp.osc.backend.osc4py3 import as_eventloop as backend  # noqa: E402
from vmcp.osc.typing import Message  # noqa: E402
from vmcp.protocol import (  # noqa: E402
    blendshape,
    blendshape_apply,
    bone_transform,
    root_transform,
    state,
)
from vmcp.protocol import time as time_message  # noqa: E402
from vmcp.typing import (  # noqa: E402
    BlendShapeKey,
    Bone,
    CalibrationMode,
    CalibrationState,
    CoordinateVector,
    ModelState,
    Quaternion,
    Scale,
    TrackingState,
)

SECONDS = float(os.environ.get("VMC_E2E_SECONDS", "5"))
FPS = 60.0
RELIABLE = QoSProfile(depth=5000, reliability=ReliabilityPolicy.RELIABLE)
Keys = BlendShapeKey("Keys", {k: k for k in BLENDSHAPES})  # vmcp wants the avatar's keys as an enum
ROOT = (np.array([0.25, 0.0, -0.4]), np.array([0.0, 0.2588190, 0.0, 0.9659258]),
        np.array([1.0, 1.0, 1.0]), np.array([0.05, 0.0, 0.1]))


@pytest.fixture(scope="module")
def sent():
    """A procedural walk at 60 Hz on an A-pose Unity rig of other proportions, with fingers,
    eyes, jaw and blendshapes, as a VMC sender's frames (float32 values)."""
    walk = synthetic_motion("walk", fps=FPS, duration=SECONDS)
    return sender_frames(walk, unity_humanoid(), root=ROOT)


def vmcp_messages(frame, t):
    """One frame as vmcp messages, in a performer's order; T is seconds since the stream began."""
    p, q, s, o = ROOT
    msgs = [Message(*root_transform(CoordinateVector(*map(float, frame.root[0])),
                                    Quaternion(*map(float, frame.root[1])), Scale(*map(float, s)),
                                    CoordinateVector(*map(float, o))))]
    msgs += [Message(*bone_transform(Bone(b), CoordinateVector(*map(float, pos)),
                                     Quaternion(*map(float, quat))))
             for b, (pos, quat) in frame.bones.items()]
    msgs += [Message(*blendshape(Keys[k], float(v))) for k, v in frame.blendshapes.items()]
    msgs.append(Message(*blendshape_apply()))
    msgs.append(Message(*state(ModelState.LOADED, CalibrationState.CALIBRATED, CalibrationMode.NORMAL,
                               TrackingState.OK)))
    msgs.append(Message(*time_message(float(t))))
    return msgs


class Marionette:
    """vmcp's receiver: events in arrival order, a frame closed by each /VMC/Ext/T."""

    def __init__(self):
        self.frames, self._bones, self._blend, self._root, self._ok = [], {}, {}, None, None

    def bone(self, e):
        self._bones[e.joint.value] = ((e.position.x, e.position.y, e.position.z),
                                      (e.rotation.x, e.rotation.y, e.rotation.z, e.rotation.w))

    def blend(self, e):
        self._blend[e.key] = e.value

    def root(self, e):
        self._root = (e.position.x, e.position.y, e.position.z)

    def ok(self, e):
        self._ok = e.model_state.value

    def time(self, e):
        self.frames.append(dict(bones=self._bones, blend=self._blend, root=self._root, ok=self._ok,
                                time=e.delta))
        self._bones, self._blend = {}, {}


def pump(osc, listener, until):
    """Run vmcp's event loop (one datagram in or out per call) and the test node until ``until``
    (a monotonic time)."""
    while True:
        for _ in range(20):
            osc.run()
        listener.executor.spin_once(timeout_sec=0)
        if time.monotonic() >= until:
            return
        time.sleep(0.001)  # the test peer must not take the cores the nodes under test need


def send(sender, msgs, bundling):
    if bundling == "bundle":
        sender.send(tuple(msgs))  # one bundle per frame
    else:
        for m in msgs:
            sender.send(m)  # every message its own bundle


def run_stream(sent, start, listener, bridge_port, out_port, middle, bundling):
    """Send every frame at 60 Hz, then wait for every output; what came back and was published."""
    states = listener.subscribe("joint_states", qos=RELIABLE)
    stylized = listener.subscribe("stylized/joint_states", qos=RELIABLE)
    blendshapes = listener.subscribe("blendshapes", qos=RELIABLE)
    diagnostics = listener.subscribe("/diagnostics", DiagnosticArray, qos=10)
    bridge = start("vmc_bridge", osc_port=bridge_port, send_port=out_port, qos_reliability="reliable",
                   qos_depth=1000)
    node_name, params = middle
    node = start(node_name, qos_reliability="reliable", qos_depth=1000, **params)
    procs = (bridge, node)
    n = listener.node
    listener.spin_until(lambda: n.count_subscribers("joint_states") >= 2
                        and n.count_subscribers("stylized/joint_states") >= 2
                        and n.count_publishers("stylized/joint_states") >= 1
                        and n.count_publishers("joint_states") >= 1, "the nodes", procs=procs)

    def bridge_status():
        for msg in reversed(diagnostics):
            for s in msg.status:
                if s.name.startswith("vmc_bridge"):
                    return {kv.key: kv.value for kv in s.values}
        return None

    if node_name == "stylizer":  # the bridge has read the stylizer's output latency
        listener.spin_until(lambda: (bridge_status() or {}).get("stylizer_latency_ms") == "16.667",
                            "the stylizer's latency in the bridge", procs=procs)
    osc = OSC(backend)
    marionette = Marionette()
    with osc.open():
        receiver = osc.create_receiver("127.0.0.1", out_port, "marionette").open()
        # The receiver's socket buffer raised as the bridge raises its own, so that a test process
        # held up by a busy machine does not lose datagrams on its side of the test.
        from osc4py3.oscchannel import get_channel

        get_channel("marionette").udpsock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, vmc.RECEIVE_BUFFER)
        for event, handler in ((BoneTransformEvent, marionette.bone), (BlendShapeEvent, marionette.blend),
                               (RootTransformEvent, marionette.root), (StateEvent, marionette.ok),
                               (RelativeTimeEvent, marionette.time)):
            on_receive(receiver, event, handler)
        sender = osc.create_sender("127.0.0.1", bridge_port, "performer").open()
        # Warm-up: one frame at a time until it has come all the way round (DDS readers and
        # writers matched both ways), then the counters' baseline; the measured stream follows.
        warm, opened = 0, time.monotonic()
        while not (marionette.frames and stylized):
            send(sender, vmcp_messages(sent[0], time.monotonic() - opened), bundling)
            warm += 1
            pump(osc, listener, time.monotonic() + 0.1)
        pump(osc, listener, time.monotonic() + 0.5)  # the last warm-up frames still in flight
        after = listener.node.get_clock().now().nanoseconds
        diagnostics.clear()
        listener.spin_until(lambda: diagnostics and stamp_ns(diagnostics[-1]) > after
                            and bridge_status() is not None, "the bridge's counters", procs=procs)
        baseline = bridge_status()
        # Every warm-up frame made, or dropped as too old for a live stream while the bridge built
        # the sender's rig on the first one (io.vmc.VmcReceiver: live means latest).
        made, dropped = int(baseline["frames"]), int(baseline["stale"]) + int(baseline["superseded"])
        assert made >= 1 and (made == warm or made + dropped >= warm), (warm, baseline)
        for topic in (states, stylized, blendshapes):
            topic.clear()
        marionette.frames.clear()
        t0 = time.monotonic()
        start_time = t0 - opened  # T: the sender's clock, as an app's frame time runs
        for k, frame in enumerate(sent):
            send(sender, vmcp_messages(frame, start_time + k / FPS), bundling)
            pump(osc, listener, t0 + (k + 1) / FPS)
        sending = time.monotonic() - t0
        deadline = time.monotonic() + 60 + SECONDS
        while len(marionette.frames) < len(sent) and time.monotonic() < deadline:
            pump(osc, listener, time.monotonic() + 0.01)
        pump(osc, listener, time.monotonic() + 0.5)  # anything still in flight (an extra frame)
    deadline = time.monotonic() + 10  # the bridge's last counts (a mismatch is checked after)
    while int(bridge_status()["sent"]) - int(baseline["sent"]) < len(sent) and time.monotonic() < deadline:
        listener.executor.spin_once(timeout_sec=0.05)
    listener.executor.spin_once(timeout_sec=1.5)
    deadline = time.monotonic() + 60  # drain what the test node's readers still hold
    while min(len(states), len(stylized), len(blendshapes)) < len(sent) and time.monotonic() < deadline:
        listener.executor.spin_once(timeout_sec=0.05)
    final = bridge_status()
    counts = {k: (int(v) - int(baseline.get(k, 0)) if v.isdigit() and k not in ("receive_buffer_bytes", "backlog_max") else v) for k, v in final.items()}
    return dict(received=marionette.frames, states=list(states), stylized=list(stylized),
                blendshapes=list(blendshapes), bridge=counts, sending_seconds=sending)


def stamp_ns(msg):
    return msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec


def shown_frames(states, latency_ns):
    """For output i (stamped as input i), the input frame whose stamp is nearest stamp_i - latency
    (the older on a tie), by the rule the stylizer and the bridge apply."""
    stamps = np.array([stamp_ns(m) for m in states])
    shown = []
    for s in stamps:
        d = np.abs(stamps - (s - latency_ns))
        d[stamps > s] = np.iinfo(np.int64).max
        shown.append(int(np.flatnonzero(d == d.min())[0]))
    return np.array(shown)


def body_errors(received, sent, shown):
    """Per output frame, the largest body-bone angle (deg) and position (m) difference from the
    sent frame its pose shows; per bone the largest angle."""
    per_bone = {}
    worst_deg, worst_m = [], []
    for r, k in zip(received, shown):
        f = sent[k]
        degs, ms = [], []
        for b in vmc.UNITY_PARENTS:
            if b not in f.bones:
                continue
            a = np.degrees(rot.angle_between(vmc.unity_to_core_rotation(f.bones[b][1]),
                                             vmc.unity_to_core_rotation(np.array(r["bones"][b][1]))))
            per_bone[b] = max(per_bone.get(b, 0.0), float(a))
            degs.append(a)
            ms.append(np.abs(np.array(r["bones"][b][0]) - f.bones[b][0]).max())
        worst_deg.append(max(degs))
        worst_m.append(max(ms))
    return np.array(worst_deg), np.array(worst_m), per_bone


def joint_distances(received, sent, shown):
    """Per output frame and body joint, the distance (m) between the received and the shown sent
    frame's joint positions on the sender's rig, relative to the hips."""
    rig = vmc.unity_rig(sent[0])

    def frame(bones, f):
        return vmc.VmcFrame({b: (np.asarray(bones[b][0]), np.asarray(bones[b][1])) for b in rig.names},
                            f.root, None, f.root_scale, f.root_offset)

    out = vmc.rig_motion(rig, [frame(r["bones"], sent[k]) for r, k in zip(received, shown)], FPS)
    ref = vmc.rig_motion(rig, [sent[k] for k in shown], FPS)
    a, b = out.global_positions(), ref.global_positions()
    return np.linalg.norm((a - a[:, :1]) - (b - b[:, :1]), axis=-1)


def check_stream(out, sent, latency_ns):
    """What every run must show; returns the measurements."""
    received, states, bridge = out["received"], out["states"], out["bridge"]
    # One output frame per pose sent, none lost on the way, nothing the kernel dropped.
    assert len(states) == len(sent)
    assert len(out["stylized"]) == len(sent)
    assert len(received) == len(sent)
    assert bridge["frames"] == len(sent) and bridge["kernel_dropped"] == 0
    assert bridge["malformed"] == bridge["incomplete"] == bridge["conversion_errors"] == 0
    assert len(out["blendshapes"]) == len(sent)
    shown = shown_frames(states, latency_ns)
    # The JointStates carry the fingers, eyes and jaw; the stylizer passes them on in step.
    extra_names = [n for n in states[0].name if n.split("_r")[0] in vmc.EXTRA_BONES]
    assert len(extra_names) == 3 * len(vmc.EXTRA_BONES)
    idx = [list(states[0].name).index(n) for n in extra_names]
    for i, msg in enumerate(out["stylized"]):
        assert list(msg.name) == list(states[i].name)
        np.testing.assert_array_equal(np.array(msg.position)[idx],
                                      np.array(states[shown[i]].position)[idx])
    # Every finger rotation and blendshape value arrives as sent, with the frame the pose shows.
    times = []
    for i, r in enumerate(received):
        f = sent[shown[i]]
        for b in vmc.EXTRA_BONES:
            assert r["bones"][b][1] == tuple(f.bones[b][1].tolist()), (i, b)
            assert r["bones"][b][0] == tuple(f.bones[b][0].tolist()), (i, b)
        assert r["blend"] == f.blendshapes, i
        assert r["root"] == tuple(ROOT[0].astype(np.float32).astype(float).tolist())
        assert r["ok"] == 1
        assert set(r["bones"]) == set(f.bones)  # every bone the sender sent
        times.append(r["time"])
        for name, value in zip(out["blendshapes"][i].name, out["blendshapes"][i].position):
            assert value == sent[i].blendshapes[name]
    steps = np.diff(times)
    assert np.all(steps > 0), [(i, times[i], times[i + 1]) for i in np.flatnonzero(steps <= 0)]  # T advances
    deg, metres, per_bone = body_errors(received, sent, shown)
    assert np.isfinite(deg).all() and np.isfinite(metres).all()
    joint_cm = joint_distances(received, sent, shown) * 100
    steps = np.diff([stamp_ns(m) for m in states]) * 1e-6
    if os.environ.get("VMC_E2E_DEBUG"):
        i = int(np.argmax(steps))
        print("largest stamp step", i, steps[max(0, i - 3): i + 4], "of", len(steps))
    return dict(frames_sent=len(sent), frames_out=len(received), seconds=SECONDS,
                sending_seconds=round(out["sending_seconds"], 2),
                stamp_step_ms=[round(float(steps.min()), 3), round(float(np.median(steps)), 3),
                               round(float(steps.max()), 3)],
                kernel_dropped=int(bridge["kernel_dropped"]), datagrams=int(bridge["datagrams"]),
                receive_buffer_bytes=int(bridge["receive_buffer_bytes"]),
                bridge_backlog_max=int(bridge["backlog_max"]), stamp_lag_max_ms=float(bridge["stamp_lag_max_ms"]),
                nominal_shown=float(np.mean(shown == np.arange(len(shown)) - round(latency_ns / 16.67e6))),
                body_deg_p50=float(np.median(deg)), body_deg_p95=float(np.percentile(deg, 95)),
                body_deg_max=float(deg.max()), body_m_max=float(metres.max()),
                hips_relative_joint_cm_mean=float(joint_cm.mean()),
                hips_relative_joint_cm_max=float(joint_cm.max()),
                per_bone_deg_max={b: round(v, 4) for b, v in per_bone.items()})


def report(name, figures):
    print(f"\n{name}: " + json.dumps(figures, indent=1))
    target = os.environ.get("VMC_E2E_REPORT")
    if target:
        os.makedirs(target, exist_ok=True)
        with open(os.path.join(target, f"{name}.json"), "w") as f:
            json.dump(figures, f, indent=1)


def free_port():
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.mark.parametrize("bundling", ["bundle", "message"])
def test_relay_returns_every_bone_as_sent(sent, start, listener, bundling):
    out = run_stream(sent, start, listener, free_port(), free_port(), ("relay", {}), bundling)
    figures = check_stream(out, sent, 0)
    assert figures["nominal_shown"] == 1.0  # no latency: every output is its own frame
    # Feet, spine, UpperChest and the root (the hips carry it) within 0.5 deg and 1 mm.
    assert figures["body_deg_max"] < 0.5 and figures["body_m_max"] < 1e-3
    report(f"relay_{bundling}", figures)


@pytest.mark.parametrize("bundling", ["bundle", "message"])
def test_stylizer_restyles_the_body_and_keeps_the_rest_in_step(sent, start, listener, bundling):
    params = dict(input_fps=FPS, target_style="elderly", alpha=1.0)
    out = run_stream(sent, start, listener, free_port(), free_port(), ("stylizer", params), bundling)
    figures = check_stream(out, sent, round(1e9 / 30 - 1e9 / 60))
    assert figures["body_deg_p50"] > 2.0  # the body is stylized, not passed through
    report(f"stylizer_elderly_{bundling}", figures)


@pytest.fixture(scope="module")
def recorded(datasets):
    """A recorded Bandai walk (in the model's training distribution, unlike the procedural walk) at
    60 Hz, at most SECONDS long, on the same rig."""
    from motion_style_ros.core.resample import resample
    from motion_style_ros.io.datasets import index_bandai, load_clip

    info = next(i for i in index_bandai(datasets) if i.content == "walk")
    clip = resample(load_clip(info), FPS)
    return sender_frames(clip[: int(SECONDS * FPS)], unity_humanoid(), root=ROOT)


@pytest.mark.parametrize("clip", ["procedural", "recorded"])
def test_stylizer_at_alpha_zero_returns_every_bone_as_sent(request, start, listener, clip):
    """alpha 0 is the performer: through the stylizer, every bone of the frame shown comes back as
    the relay gives it back (the stream's latency later)."""
    frames = request.getfixturevalue("sent" if clip == "procedural" else "recorded")
    params = dict(input_fps=FPS, target_style="elderly", alpha=0.0)
    out = run_stream(frames, start, listener, free_port(), free_port(), ("stylizer", params), "bundle")
    figures = check_stream(out, frames, round(1e9 / 30 - 1e9 / 60))
    assert figures["body_deg_max"] < 0.5 and figures["body_m_max"] < 1e-3, figures
    report(f"stylizer_alpha0_{clip}", figures)
