"""The stylizer node with ``backend: most`` and ``backend: saae`` (windowed backends that take a
reference clip, no latent seeds) as a real process over DDS.

A random-weight model of each (the real interface, a 16-frame window) serves one performer with
reliable QoS, one node process per backend. The outputs are checked against an offline session
made as the node makes it (``runtime.stylizer_settings.sessions``) and fed the same frames and
stamps; ``target_style``, ``reference`` and ``latent_seed`` change through the real
``~/set_parameters`` service.
"""

import numpy as np
import pytest

torch = pytest.importorskip("torch", reason="random-weight MoST and SAAE models: pip install '.[train]'")

import ros_helpers
from bad_files import unretargetable_clip, unusable_clips
from diagnostic_msgs.msg import DiagnosticArray
from rcl_interfaces.srv import GetParameters, SetParameters
from rclpy.parameter import Parameter
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from ros_helpers import Listener, message, replay, stamps, start_node, stop
from sensor_msgs.msg import JointState

from motion_style_ros.core.synthetic import synthetic_motion
from motion_style_ros.io.canonical import canonical_clip
from motion_style_ros.io.joint_state import JointStateLayout
from motion_style_ros.runtime import stylizer_settings
from motion_style_ros.runtime.backends import BACKENDS

STYLES = ["active", "elderly", "exhausted", "feminine", "masculine", "normal", "youthful"]
FPS = 30.0
T0 = 1_700_000_000 * 10**9  # ns
PERIOD = round(1e9 / FPS)
LOOKAHEAD, HOP = 8, 4  # the models' window is 16 frames
LAYOUT = JointStateLayout.canonical()
RELIABLE = QoSProfile(history=HistoryPolicy.KEEP_ALL, reliability=ReliabilityPolicy.RELIABLE)
REFERENCE = "bandai-namco/Bandai-Namco-Research-Motiondataset-2/data/dataset-2_walk_elderly_001.bvh"
# the frames at which the tests below change the node's parameters, in the order they run
STYLE_AT, REFERENCE_AT, SEED_AT, EMPTIED_AT = 120, 180, 300, 360


@pytest.fixture(scope="module", params=["most", "saae"])
def backend(request):
    return request.param


@pytest.fixture(scope="module")
def model(backend, tmp_path_factory):
    path = tmp_path_factory.mktemp(backend) / f"{backend}.onnx"
    if backend == "most":
        from motion_style_ros.training.most.export import export_random_model

        export_random_model(path, STYLES)
    else:
        from motion_style_ros.training.saae.export import export_random_model

        export_random_model(path, STYLES, variant="model2")
    return path


@pytest.fixture(scope="module")
def frames():
    """A synthetic walk in the canonical layout as ``(stamp ns, positions)``."""
    values = LAYOUT.encode_motion(synthetic_motion("walk", FPS, 16.0))
    return [(T0 + k * PERIOD, v) for k, v in enumerate(values)]


@pytest.fixture(scope="module")
def clip(datasets):
    return canonical_clip(str(datasets / REFERENCE))


@pytest.fixture(scope="module")
def node(backend, model, ros_env, tmp_path_factory):
    log = tmp_path_factory.mktemp(f"stylizer_{backend}") / "stylizer.log"
    proc = start_node("stylizer", ros_env, log=log, backend=backend, model=model, input_fps=FPS,
                      lookahead=LOOKAHEAD, hop=HOP, qos_reliability="reliable", qos_depth=1000)
    listener = Listener(f"{backend}_test")
    publisher = listener.node.create_publisher(JointState, "joint_states", RELIABLE)
    got = listener.subscribe("stylized/joint_states", qos=RELIABLE)
    diagnostics = listener.subscribe("/diagnostics", DiagnosticArray, RELIABLE)
    client = listener.node.create_client(SetParameters, "/stylizer/set_parameters")
    getter = listener.node.create_client(GetParameters, "/stylizer/get_parameters")
    listener.spin_until(lambda: publisher.get_subscription_count() and
                        listener.subscriptions["stylized/joint_states"].get_publisher_count(),
                        f"the stylizer ({backend})", procs=[proc])

    class Rig:
        pass

    rig = Rig()
    rig.proc, rig.got, rig.log, rig.listener, rig.diagnostics = proc, got, log, listener, diagnostics

    def send(batch):
        expected = len(got) + len(batch)
        for stamp_ns, positions in batch:
            publisher.publish(message(stamp_ns, LAYOUT.names, positions))
        listener.spin_until(lambda: len(got) >= expected, f"{expected} stylized states", procs=[proc])

    set_parameters = ros_helpers.parameter_setter(listener, client, diagnostics, proc)

    def parameter(name):
        return listener.call(getter, GetParameters.Request(names=[name]), procs=[proc]).values[0]

    rig.send, rig.set_parameters, rig.parameter = send, set_parameters, parameter
    yield rig
    listener.close()
    stop(proc)
    print(log.read_text())  # shown by pytest when a test fails


def offline(backend, model, frames, controls=None):
    """What a session made as the node makes it (its settings from the same parameters) makes of
    ``frames`` (JointState positions); ``controls[k](session)`` runs before frame k."""
    values = {**{p.name: p.default for p in stylizer_settings.PARAMETERS}, "backend": backend,
              "input_fps": FPS, "lookahead": LOOKAHEAD, "hop": HOP}
    (session,) = stylizer_settings.sessions(BACKENDS[backend], str(model), 1, values)
    return np.array([e for e, _, _ in replay(session, LAYOUT, frames, controls)])


def difference(a, b):
    return ros_helpers.difference(a, b, LAYOUT)


def pose_difference(a, b):
    """:func:`difference` of the joints alone: the stylized root follows the performer's with a
    time constant of seconds, so it remembers a past style longer than the poses do."""
    a, b = np.array(a, dtype=float), np.array(b, dtype=float)
    a[..., :3] = b[..., :3] = 0.0
    return difference(a, b)


def ELDERLY(session):
    """What the node's ``target_style: elderly`` does to a session."""
    session.set_style("elderly")


def with_reference(clip):
    """What the node does to a session when ``reference`` names ``clip`` (target style elderly):
    every style back to its own input, then the clip's code over the target style's."""
    def control(session):
        session.clear_reference()
        session.use_reference(*session.reference_codes(clip), "elderly")
    return control


def EMPTIED(session):
    """What the node's ``reference: ''`` does to a session (of a backend without seeds)."""
    session.clear_reference()


def test_the_registry_lists_both_as_reference_backends_without_seeds(backend):
    spec = BACKENDS[backend]
    assert spec.reference_clips and spec.lookahead and not spec.latent_seeds


def test_frames_are_stylized_as_offline_at_the_input_rate(node, backend, model, frames):
    node.send(frames[:STYLE_AT])
    got = node.got
    assert stamps(got).tolist() == [s for s, _ in frames[:STYLE_AT]]  # one out per frame in, its stamp
    assert all(list(m.name) == LAYOUT.names for m in got)
    out = np.array([m.position for m in got])
    assert out.shape == (STYLE_AT, len(LAYOUT.names)) and np.isfinite(out).all()
    assert difference(out, offline(backend, model, frames[:STYLE_AT])) < 1e-5
    assert difference(out[20:], np.array([v for _, v in frames[20:STYLE_AT]])) > 1e-2  # restyled


def test_the_target_style_changes_live_and_an_unknown_one_is_refused(node, backend, model, frames):
    (refused,) = node.set_parameters(target_style="proud")
    assert not refused.successful
    assert f"unknown style 'proud'; this model knows: {', '.join(STYLES)}" in refused.reason, refused.reason
    (result,) = node.set_parameters(target_style="elderly")
    assert result.successful, result.reason
    node.send(frames[STYLE_AT:REFERENCE_AT])
    out = np.array([m.position for m in node.got])
    assert difference(out, offline(backend, model, frames[:REFERENCE_AT], {STYLE_AT: ELDERLY})) < 1e-5
    unchanged = offline(backend, model, frames[:REFERENCE_AT])
    assert difference(out[STYLE_AT + 10:], unchanged[STYLE_AT + 10:]) > 1e-2


def test_bad_reference_clips_are_refused_with_their_reason(node, tmp_path):
    """As for stgcn (test_stylizer_node_stgcn); the short clip's reason gives this model's window."""
    for path, reason in unusable_clips(tmp_path, FPS):
        if reason == "too short":
            reason = "too short: 0.50 s; it needs at least 0.5 s (16 frames at 30 fps)"
        (result,) = node.set_parameters(reference=path)
        assert not result.successful and reason in result.reason, (path, result.reason)
    assert node.parameter("reference").string_value == ""
    assert node.proc.poll() is None


def test_a_reference_clip_is_used_live(node, backend, model, frames, datasets, clip):
    (result,) = node.set_parameters(reference=str(datasets / REFERENCE))
    assert result.successful, result.reason
    node.send(frames[REFERENCE_AT:SEED_AT])
    out = np.array([m.position for m in node.got])
    expected = offline(backend, model, frames[:SEED_AT], {STYLE_AT: ELDERLY, REFERENCE_AT: with_reference(clip)})
    assert difference(out, expected) < 1e-5  # and the refused clips before it changed nothing
    without = offline(backend, model, frames[:SEED_AT], {STYLE_AT: ELDERLY})
    assert pose_difference(out[REFERENCE_AT + 10:], without[REFERENCE_AT + 10:]) > 0.1


def test_a_latent_seed_is_accepted_and_ignored(node, backend, model, frames, clip):
    """These backends have no latent seeds: the node takes the parameter (as the recurrent backend
    does) and nothing changes; the reference clip in use stays in use."""
    (result,) = node.set_parameters(latent_seed=7)
    assert result.successful, result.reason
    assert node.parameter("latent_seed").integer_value == 7
    node.send(frames[SEED_AT:EMPTIED_AT])
    out = np.array([m.position for m in node.got])
    expected = offline(backend, model, frames[:EMPTIED_AT], {STYLE_AT: ELDERLY, REFERENCE_AT: with_reference(clip)})
    assert difference(out, expected) < 1e-5
    dropped = offline(backend, model, frames[:EMPTIED_AT],
                      {STYLE_AT: ELDERLY, REFERENCE_AT: with_reference(clip), SEED_AT: EMPTIED})
    assert pose_difference(out[SEED_AT + 10:], dropped[SEED_AT + 10:]) > 0.1  # the clip would show


def test_emptying_the_reference_goes_back_to_the_styles_own(node, backend, model, frames, clip):
    (result,) = node.set_parameters(reference="")
    assert result.successful, result.reason
    node.send(frames[EMPTIED_AT:])
    out = np.array([m.position for m in node.got])
    assert len(out) == len(frames) and node.proc.poll() is None
    controls = {STYLE_AT: ELDERLY, REFERENCE_AT: with_reference(clip)}
    expected = offline(backend, model, frames, {**controls, EMPTIED_AT: EMPTIED})
    assert difference(out, expected) < 1e-5
    # back: the poses once the windows with the clip's code are gone (blend 9 frames, window 16,
    # lookahead 8) are the ones of a stream that never had a reference, within what the stylized
    # root's memory leaves (the root follows the performer's over 2 s); with the clip still in
    # use they are far from them
    never = offline(backend, model, frames, {STYLE_AT: ELDERLY})
    kept = offline(backend, model, frames, controls)
    settled = EMPTIED_AT + 40
    back, away = pose_difference(out[settled:], never[settled:]), pose_difference(kept[settled:], never[settled:])
    assert back < 0.1 * away, (back, away)


def test_a_clip_the_worker_cannot_use_is_reported_and_the_reference_goes_back(node, tmp_path):
    """A well-formed BVH, so the set is accepted at once; the worker thread then finds it is no
    humanoid, logs why (naming what '' means here: no latent seed) and sets ``reference`` back."""
    broken = unretargetable_clip(tmp_path)
    request = SetParameters.Request(parameters=[Parameter("reference", value=broken).to_parameter_msg()])
    client = node.listener.node.create_client(SetParameters, "/stylizer/set_parameters")
    (result,) = node.listener.call(client, request, procs=[node.proc]).results
    assert result.successful, result.reason
    node.listener.spin_until(lambda: "parameter reference:" in node.log.read_text(), "the worker's error",
                             procs=[node.proc])
    node.listener.spin_until(lambda: node.parameter("reference").string_value == "", "the reference set back",
                             procs=[node.proc])
    line = next(x for x in node.log.read_text().splitlines() if "parameter reference:" in x)
    assert "keeping \"the styles' own inputs\"" in line, line
    assert node.proc.poll() is None
