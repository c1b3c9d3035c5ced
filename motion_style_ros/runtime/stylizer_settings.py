"""The stylizer node's parameters without ROS: every one with its default, range and description
(the node declares them from :data:`PARAMETERS`; ``config/stylizer.yaml`` lists them), the checks
of a value at start and of a live change, the sessions the settings build, and how a live change
reaches them. The defaults of the sessions' own settings come from
:mod:`~motion_style_ros.runtime.defaults`, which ``stylize``, ``eval`` and ``bench`` read too.
"""

from __future__ import annotations

import array
from dataclasses import dataclass, replace

from motion_style_ros.core.intensity import PARTS, check_part_alpha
from motion_style_ros.errors import MotionStyleError
from motion_style_ros.runtime.backends import BACKENDS, Backend, with_feature
from motion_style_ros.runtime.defaults import DEFAULTS, StreamSettings
from motion_style_ros.runtime.intake import Bounds
from motion_style_ros.runtime.trajectory import VELOCITIES
from motion_style_ros.runtime.warmup import warm_kernels
from motion_style_ros.runtime.stgcn import MAX_SPREAD

# Parameters that change live, with their types (checked by the node: rclpy's own message would
# name the types by number).
DYNAMIC = {"target_style": str, "alpha": float, "part_alpha": list, "mix_style": str, "mix_weight": float,
           "latent_seed": int, "seed_spread": float, "reference": str, "frame_id": str}
# what an array parameter's value may arrive as (rclpy gives a set double array as array('d'))
_SEQUENCES = (list, tuple, array.array)
TYPE_NAMES = {str: "string", float: "double", int: "integer", bool: "bool", list: "array",
              type(None): "nothing (not set)"}


@dataclass(frozen=True)
class Parameter:
    name: str
    default: object
    description: str
    low: float | None = None
    high: float | None = None

    @property
    def live(self) -> bool:
        return self.name in DYNAMIC


_BOUNDS = Bounds()
# the backends each backend-specific parameter is for (from the registry, so that a new entry is named)
_WINDOWS, _SEEDS, _REFERENCES = (", ".join(with_feature(feature))
                                  for feature in ("lookahead", "latent_seeds", "reference_clips"))
_SEEDLESS = ", ".join(b for b in BACKENDS if not BACKENDS[b].latent_seeds)
# Every parameter but target_style (its default is the model's neutral style) and the QoS ones
# (nodes.parameters.Parameters.qos, as for every node of the package).
PARAMETERS = (
    Parameter("performers", [""], "topic prefix of each performer (one session each): performer N "
              "subscribes N/joint_states and publishes N/stylized/...; '' = the node's namespace"),
    Parameter("model", "", "stylizer model: a shipped model's file name (models/) or a path, its JSON "
              "model card beside it; '' = the backend's shipped model"),
    Parameter("backend", "recurrent", f"stylizer backend: {', '.join(BACKENDS)}"),
    Parameter("window", 0, f"{_WINDOWS}: frames per window (stgcn: a multiple of 4); 0 = the model card's",
              0, 1024),
    Parameter("style_bank", "", "stgcn, most: a style bank file of enrolled styles (motion-style style add); "
              "'' = the model's own (<model>_styles.json) if there is one"),
    Parameter("hop", DEFAULTS["hop"], f"{_WINDOWS}: model frames between two windows", 1, 1024),
    Parameter("lookahead", DEFAULTS["lookahead"], f"{_WINDOWS}: model frames of the future each output frame "
              "waits for (latency lookahead / model fps); more is smoother", 0, 1023),
    Parameter("input_fps", 0.0, "nominal input rate in Hz (0: the model's rate); sets the output "
              "latency, 1/model_fps - 1/input_fps", 0.0, 1000.0),
    Parameter("blend_seconds", DEFAULTS["blend_seconds"], "seconds over which a style/alpha/mix change "
              "blends in", 0.0, 60.0),
    Parameter("layout", "", "JointState layout YAML (config/layouts/); '' = canonical"),
    Parameter("trajectory_points", 6, "points per JointTrajectory chunk", 1, 120),
    Parameter("trajectory_velocities", VELOCITIES[0], "velocities of the trajectory points: inner (all "
              "but each chunk's last, which JointTrajectoryController accepts by default), all (set its "
              "allow_nonzero_velocity_at_trajectory_end), none (positions only)"),
    Parameter("max_latency_ms", 20.0, "diagnostics: a processing latency p99 over this is a warning",
              0.1, 1e4),
    Parameter("robot_urdf", "", "a humanoid robot's URDF: the stylized motion is also mapped onto its "
              "joints (stylized/robot/...); '' = none"),
    Parameter("robot_map", "", "robot_urdf: a YAML body map naming its knee, elbow, ... joints where the "
              "names do not say; '' = found from the URDF"),
    Parameter("publish_markers", False, "publish the stylized skeleton as a visualization_msgs/MarkerArray "
              "on stylized/markers"),
    Parameter("threads", 1, "ONNX Runtime threads per performer", 1, 16),
    Parameter("foot_lock", DEFAULTS["foot_lock"], "keep the feet the input plants planted in the output "
              "(causal leg IK)"),
    Parameter("follow_seconds", DEFAULTS["follow_seconds"] or 0.0, "time constant (s) with which the stylized "
              "root trajectory is pulled towards the input's, so the avatar stays with its performer; "
              "0 = free (the style's own speed and turns, drifting)", 0.0, 600.0),
    Parameter("pipelined", DEFAULTS["pipelined"], "publish each frame before running the model frames it "
              "does not need, which then run between frames: every frame costs an interpolation on its "
              "way through, at one input frame more latency (1/input_fps)"),
    Parameter("alpha", DEFAULTS["alpha"], "intensity of the style: 0 = the performer's own motion, exactly; 1 = the "
              "full style; between, every joint turned that far towards the style", 0.0, 1.0),
    Parameter("part_alpha", [1.0] * len(PARTS), f"alpha per body part, {', '.join(PARTS)} (legs with the "
              "pelvis and the root's path), each 0 to 1: [1.0, 1.0, 0.0] restyles torso and arms and keeps "
              "the legs as performed"),
    Parameter("mix_style", "", "a second style mixed in with mix_weight; '' = none"),
    Parameter("mix_weight", 0.0, "weight of mix_style: 0 = target_style alone, 1 = mix_style alone",
              0.0, 1.0),
    Parameter("latent_seed", 0, f"{_SEEDS}: seed of the style codes (the same seed, the same codes on every "
              f"machine); {_SEEDLESS} have no latent seeds and ignore it", 0, 2**31 - 1),
    Parameter("seed_spread", DEFAULTS["seed_spread"], f"{_SEEDS}: how far the seeds' codes lie from their "
              "style's mean code: 1 = as trained, 0 = one code per style, more = seeds differ more (the "
              "style less surely)", 0.0, MAX_SPREAD),
    Parameter("reference", "", f"{_REFERENCES}: a BVH clip whose style code (style encoder) replaces the "
              "target style's: move like this recording; '' = the style's own (stgcn: the latent seed's code)"),
    Parameter("frame_id", "", "header.frame_id of the outputs; '' = the input's (markers: 'world')"),
    Parameter("max_stamp_jump", _BOUNDS.max_stamp_jump, "s a frame's stamp may run ahead of the time "
              "since the previous frame arrived (and a first frame ahead of its arrival); more is "
              "dropped", 1e-3, 1e6),
    Parameter("restart_seconds", _BOUNDS.restart_seconds, "s of frames on a new clock or at a new place "
              "(clock reset, teleport) after which the stream restarts on them by itself", 1e-3, 600.0),
    Parameter("max_root_distance", _BOUNDS.max_root_distance, "m from the origin (each axis) beyond "
              "which a frame's root is dropped", 1e-3, 1e9),
    Parameter("max_root_speed", _BOUNDS.max_root_speed, "m/s the root may move between two frames; "
              "faster is dropped", 1e-3, 1e6),
    Parameter("max_angle", _BOUNDS.max_angle, "rad beyond which an angle is dropped as no rotation",
              1.0, 1e9),
)


NAMES = (*(p.name for p in PARAMETERS), "target_style")  # every parameter the node declares but QoS


def target_style(styles: list[str], neutral: str) -> Parameter:
    """``target_style``, whose default and description come from the model."""
    return Parameter("target_style", neutral, f"style to restyle into: {', '.join(styles)}")


def check_start(values: dict) -> Backend:
    """The backend the read-at-start values ask for, or a one-line reason they do not go together."""
    if values["trajectory_velocities"] not in VELOCITIES:
        raise MotionStyleError(f"parameter trajectory_velocities is {values['trajectory_velocities']!r}; "
                               f"allowed: {', '.join(VELOCITIES)}")
    backend = values["backend"]
    if backend not in BACKENDS:
        raise MotionStyleError(f"parameter backend is {backend!r}; allowed: {', '.join(BACKENDS)}")
    spec = BACKENDS[backend]
    if values["style_bank"] and not spec.style_bank:
        raise MotionStyleError(f"parameter style_bank needs backend {' or '.join(with_feature('style_bank'))} "
                               f"(styles enrolled from clips); {backend} has a fixed set of styles")
    check_prefixes(values["performers"])
    return spec


def check_prefixes(prefixes: list[str]) -> None:
    """The ``performers`` parameter's check (the stylizer's and the relay's): a prefix twice would
    stylize or republish its stream twice."""
    if not prefixes or len(set(prefixes)) != len(prefixes):
        raise MotionStyleError(f"parameter performers is {list(prefixes)}; give distinct topic "
                               "prefixes, e.g. ['alice', 'bob'] (or [''] for one performer)")


def bounds(values: dict) -> Bounds:
    """The intake's bounds from the parameters of the same names."""
    return Bounds(**{k: values[k] for k in ("max_stamp_jump", "restart_seconds", "max_root_distance",
                                            "max_root_speed", "max_angle")})


def sessions(spec: Backend, model: str, count: int, values: dict) -> list:
    """One session per performer, each running its model frames (and windows) on other input
    frames than the one before it (one in input_fps / model fps runs the model), so that streams in
    step do not all run the model on the same one: a window of two performers at once stalled the
    stream 14 ms at 120 Hz."""
    stream = StreamSettings(blend_seconds=values["blend_seconds"], follow_seconds=values["follow_seconds"] or None,
                            foot_lock=values["foot_lock"], pipelined=values["pipelined"])
    options = dict(input_fps=values["input_fps"] or None, threads=values["threads"], window=values["window"] or None,
                   hop=values["hop"], lookahead=values["lookahead"], bank=values["style_bank"] or None)
    warm_kernels()  # before the node subscribes: a stream's first frames do not wait for numba
    first = spec.open_session(model, stream, **options)
    spread = max(1, round(first.input_fps / first.fps))
    return [first] + [spec.open_session(model, replace(stream, phase_seconds=(k % spread) / first.input_fps), **options)
                      for k in range(1, count)]


def wrong_type(key: str, value, want: type) -> str | None:
    """Why ``value`` of the live parameter ``key`` is not of type ``want``, with ROS's type names
    (rclpy's own message would name them by number), or None."""
    if type(value) is want or (want is list and isinstance(value, _SEQUENCES)):
        return None
    got = TYPE_NAMES.get(type(value), type(value).__name__)
    return f"{key} must be of type {TYPE_NAMES[want]}, got {got} {value!r}"


def problem(key: str, value, styles: list[str], spec: Backend) -> str | None:
    """Why ``value`` is no value for the live parameter ``key``, or None. (Ranges are checked by the
    descriptors before the callback runs.)"""
    if reason := wrong_type(key, value, DYNAMIC[key]):
        return reason
    if key in ("target_style", "mix_style") and value not in styles and not (
            key == "mix_style" and value == ""):
        return (f"unknown style {value!r}; this model knows: {', '.join(styles)}"
                + (" ('' = no mix)" if key == "mix_style" else ""))
    if key == "part_alpha":
        try:
            check_part_alpha(value)
        except MotionStyleError as exc:
            return str(exc)
    if key == "reference" and value and not spec.reference_clips:
        return (f"a reference clip needs backend {' or '.join(with_feature('reference_clips'))} (its "
                f"style encoder); this node runs {spec.name}: '' is the only value allowed")
    return None


def apply(sessions_: list, spec: Backend, settings: dict, changes: dict, reference: tuple | None) -> None:
    """Hand changed controls to every session; they blend in from the next frame. ``settings``: the
    values before the change; ``reference``: the reference clip's codes to use, if any (a clip stays
    in use when the target style or the seed changes: the seed's codes are derived again, then the
    clip's replace the target style's)."""
    settings = {**settings, **changes}
    for session in sessions_:
        if "target_style" in changes:
            session.set_style(changes["target_style"])
        if "alpha" in changes:
            session.set_alpha(changes["alpha"])
        if "part_alpha" in changes:
            session.set_part_alpha(changes["part_alpha"])
        if "mix_style" in changes or "mix_weight" in changes:
            session.set_mix(settings["mix_style"] or None, settings["mix_weight"])
        dropped = "reference" in changes and not settings["reference"]
        if spec.latent_seeds and ({"latent_seed", "seed_spread"} & changes.keys() or dropped):
            session.set_seed(settings["latent_seed"], spread=settings["seed_spread"])
        elif spec.reference_clips and not spec.latent_seeds and (dropped or reference is not None):
            session.clear_reference()  # the styles' own inputs, a new reference's over its style
        if reference is not None:
            session.use_reference(*reference, settings["target_style"])
