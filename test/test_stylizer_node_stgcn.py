"""The stylizer node with ``backend: stgcn`` as a real process over DDS.

A random-weight ST-GCN model (the real interface) serves one performer with reliable QoS. The
outputs are checked against an offline :class:`StgcnSession` fed the same frames and stamps;
``latent_seed`` and ``reference`` change through the real ``~/set_parameters`` service.
"""

import numpy as np
import pytest
import ros_helpers
from bad_files import unretargetable_clip, unusable_clips
from onnx_fixtures import windowed_model
from rcl_interfaces.srv import GetParameters, SetParameters
from rclpy.parameter import Parameter
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from ros_helpers import Listener, message, replay, stamps, start_node, stop
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from sensor_msgs.msg import JointState

from motion_style_ros.core.synthetic import synthetic_motion
from motion_style_ros.io.joint_state import JointStateLayout
from motion_style_ros.io.canonical import canonical_clip
from motion_style_ros.runtime.stgcn import StgcnSession

STYLES = ["active", "elderly", "exhausted", "feminine", "masculine", "normal", "youthful"]
FPS = 30.0
T0 = 1_700_000_000 * 10**9  # ns
PERIOD = round(1e9 / FPS)
LOOKAHEAD, HOP = 8, 4
LAYOUT = JointStateLayout.canonical()
RELIABLE = QoSProfile(history=HistoryPolicy.KEEP_ALL, reliability=ReliabilityPolicy.RELIABLE)
REFERENCE = "bandai-namco/Bandai-Namco-Research-Motiondataset-2/data/dataset-2_walk_elderly_001.bvh"


@pytest.fixture(scope="module")
def model(tmp_path_factory):
    return windowed_model(tmp_path_factory.mktemp("stgcn") / "stgcn.onnx", STYLES)


@pytest.fixture(scope="module")
def frames():
    """A synthetic walk in the canonical layout as ``(stamp ns, positions)``."""
    values = LAYOUT.encode_motion(synthetic_motion("walk", FPS, 12.0))
    return [(T0 + k * PERIOD, v) for k, v in enumerate(values)]


@pytest.fixture(scope="module")
def node(model, ros_env, tmp_path_factory):
    log = tmp_path_factory.mktemp("stylizer_stgcn") / "stylizer.log"
    proc = start_node("stylizer", ros_env, log=log, backend="stgcn", model=model, input_fps=FPS,
                      lookahead=LOOKAHEAD, hop=HOP, qos_reliability="reliable", qos_depth=1000)
    listener = Listener("stgcn_test")
    publisher = listener.node.create_publisher(JointState, "joint_states", RELIABLE)
    got = listener.subscribe("stylized/joint_states", qos=RELIABLE)
    client = listener.node.create_client(SetParameters, "/stylizer/set_parameters")
    listener.spin_until(lambda: publisher.get_subscription_count() and
                        listener.subscriptions["stylized/joint_states"].get_publisher_count(),
                        "the stylizer", procs=[proc])

    def send(batch):
        expected = len(got) + len(batch)
        for stamp_ns, positions in batch:
            publisher.publish(message(stamp_ns, LAYOUT.names, positions))
        listener.spin_until(lambda: len(got) >= expected, f"{expected} stylized states", procs=[proc])

    diagnostics = listener.subscribe("/diagnostics", DiagnosticArray, RELIABLE)

    set_parameters = ros_helpers.parameter_setter(listener, client, diagnostics, proc)

    set_parameters.raw = lambda request: listener.call(client, request, procs=[proc]).results
    set_parameters.diagnostics, set_parameters.listener = diagnostics, listener
    yield send, set_parameters, got, proc
    listener.close()
    stop(proc)
    print(log.read_text())  # shown by pytest when a test fails


def SEEDED(session):
    """What the node's ``latent_seed: 7`` and ``seed_spread: 2.0`` do to a session."""
    session.set_seed(7, spread=2.0)


def offline(model, frames, controls=None):
    """What a fresh session with the node's settings makes of ``frames`` (JointState positions);
    ``controls[k](session)`` runs before frame k."""
    session = StgcnSession(model, 1, FPS, follow_seconds=2.0, lookahead=LOOKAHEAD, hop=HOP)
    return np.array([e for e, _, _ in replay(session, LAYOUT, frames, controls)])


def difference(a, b):
    return ros_helpers.difference(a, b, LAYOUT)


def test_frames_are_stylized_as_offline_and_the_seed_changes_live(node, model, frames):
    send, set_parameters, got, _ = node
    send(frames[:120])
    assert stamps(got).tolist() == [s for s, _ in frames[:120]]
    assert difference([m.position for m in got], offline(model, frames[:120])) < 1e-5

    (seed, spread) = set_parameters(latent_seed=7, seed_spread=2.0)
    assert seed.successful and spread.successful, (seed.reason, spread.reason)
    send(frames[120:240])
    out = np.array([m.position for m in got])
    seeded = offline(model, frames[:240], {120: SEEDED})
    assert difference(out, seeded) < 1e-5
    assert difference(out[130:], offline(model, frames[:240])[130:]) > 1e-4  # the seed took effect


def test_reference_clips_are_read_checked_and_used(node, model, frames, datasets, tmp_path):
    send, set_parameters, got, proc = node
    for path, reason in unusable_clips(tmp_path, FPS):  # refused at once, never opened if no file
        (result,) = set_parameters(reference=path)
        assert not result.successful and reason in result.reason, (path, result.reason)
    # (~/set_parameters applies its parameters one by one, each through the node's callback)
    for change in ({"target_style": "elderly"}, {"reference": str(datasets / REFERENCE)}):
        (result,) = set_parameters(**change)
        assert result.successful, result.reason
    send(frames[240:])  # the stream kept flowing through every change, good or bad
    assert proc.poll() is None and len(got) == len(frames)
    clip = canonical_clip(str(datasets / REFERENCE))

    def reference(session):
        session.set_style("elderly")
        session.set_reference(clip, "elderly")

    expected = offline(model, frames, {120: SEEDED, 240: reference})
    out = np.array([m.position for m in got])
    assert difference(out, expected) < 1e-5  # the rejected clips changed nothing
    assert difference(out[250:], offline(model, frames, {120: SEEDED})[250:]) > 1e-4


def test_a_reference_stays_in_use_when_the_seed_changes(node, model, frames, datasets):
    """The ``reference`` parameter still names the clip after a ``latent_seed`` change, and the
    clip's code is still the one in use."""
    send, set_parameters, got, _ = node
    assert len(got) == len(frames)  # after the reference test: its clip is in use
    roots = np.array([v[:3] for _, v in frames])
    lap = roots[-1] - roots[0] + (roots[1] - roots[0])  # the walk goes on from where it ended
    more = [(T0 + (len(frames) + k) * PERIOD, np.concatenate([v[:3] + lap, v[3:]]))
            for k, (_, v) in enumerate(frames[:90])]
    send(more[:30])
    (result,) = set_parameters(latent_seed=9)
    assert result.successful, result.reason
    send(more[30:])
    clip = canonical_clip(str(datasets / REFERENCE))

    def reference(session):
        session.set_style("elderly")
        session.set_reference(clip, "elderly")

    def reseeded(keep):
        def control(session):
            session.set_seed(9, spread=2.0)
            if keep:
                session.set_reference(clip, "elderly")
        return control

    n = len(frames)
    out = np.array([m.position for m in got])
    kept = offline(model, frames + more, {120: SEEDED, 240: reference, n + 30: reseeded(True)})
    dropped = offline(model, frames + more, {120: SEEDED, 240: reference, n + 30: reseeded(False)})
    assert difference(out, kept) < 1e-5
    assert difference(out[n + 40:], dropped[n + 40:]) > 1e-4


def test_an_enrolled_style_of_the_style_bank_is_a_target_style(model, ros_env, datasets, tmp_path):
    from motion_style_ros.runtime import style_bank

    session = StgcnSession(model, lookahead=LOOKAHEAD)
    entry = session.enrol([canonical_clip(str(datasets / REFERENCE))], ["walk_elderly"])
    bank = tmp_path / "mine.json"
    style_bank.write(bank, {"bouncy": entry}, "stgcn", session.model_digest)
    # started straight into the enrolled style: an unknown one would stop it at start-up
    proc = start_node("stylizer", ros_env, remaps={"__ns": "/bank"}, backend="stgcn", model=model,
                      style_bank=str(bank), target_style="bouncy", lookahead=LOOKAHEAD)
    listener = Listener("bank_test")
    try:
        client = listener.node.create_client(SetParameters, "/bank/stylizer/set_parameters")

        def set_style(name):
            request = SetParameters.Request(parameters=[Parameter("target_style", value=name).to_parameter_msg()])
            return listener.call(client, request, procs=[proc]).results[0]

        assert set_style("normal").successful
        assert set_style("bouncy").successful
        refused = set_style("nope")
        assert not refused.successful and "bouncy" in refused.reason
    finally:
        listener.close()
        stop(proc)


def test_a_clip_the_worker_cannot_use_is_reported_and_the_reference_goes_back(node, tmp_path):
    """The file is a well-formed BVH, so the set is accepted at once; the worker thread then finds
    it is no humanoid, logs why, sets ``reference`` back to the clip in use and says so on
    /diagnostics."""
    _, set_parameters, _, proc = node
    broken = unretargetable_clip(tmp_path)
    listener, diagnostics = set_parameters.listener, set_parameters.diagnostics
    diagnostics.clear()
    listener.spin_until(lambda: diagnostics, "a status", procs=[proc])
    before = {kv.key: kv.value for kv in diagnostics[-1].status[0].values}["reference"]
    (result,) = set_parameters.raw(SetParameters.Request(
        parameters=[Parameter("reference", value=str(broken)).to_parameter_msg()]))
    assert result.successful, result.reason
    getter = listener.node.create_client(GetParameters, "/stylizer/get_parameters")

    def parameter():
        return listener.call(getter, GetParameters.Request(names=["reference"]), procs=[proc]).values[0].string_value

    listener.spin_until(lambda: parameter() == before, "the reference set back", procs=[proc])
    diagnostics.clear()
    listener.spin_for(1.5)
    assert {kv.key: kv.value for kv in diagnostics[-1].status[0].values}["reference"] == before
    (warning,) = [status for status in diagnostics[-1].status if status.name == "stylizer: reference"]
    assert warning.level == DiagnosticStatus.WARN and "not a humanoid skeleton" in warning.message, warning
    assert proc.poll() is None
