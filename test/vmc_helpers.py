"""VMC test material: a Unity humanoid rig of other proportions with an A-pose rest, and clips on it
as a VMC sender streams them (body, fingers, eyes, jaw, blendshapes)."""

import numpy as np

from motion_style_ros.core import rotations as rot
from motion_style_ros.core.motion import Motion
from motion_style_ros.core.retarget import MAPS, Retargeter, find_map
from motion_style_ros.core.skeleton import Skeleton
from motion_style_ros.io import vmc
from motion_style_ros.io.vmc.protocol import EXTRA_PARENTS

BLENDSHAPES = ("A", "I", "U", "E", "O", "Blink_L", "Blink_R", "Joy")


def unity_humanoid(scale=1.1, arm=1.15, leg=0.92, a_pose_deg=40.0, toe_drop=0.05):
    """A Unity HumanBodyBones rig (core frame, metres) whose identity pose is an A-pose: the arms
    hang ``a_pose_deg`` below horizontal, the toes sit ``toe_drop`` below the ankle, limbs have
    other lengths than the canonical rig's, and it has UpperChest, eyes, jaw and every finger."""
    down = np.radians(a_pose_deg)
    off = {
        "Hips": [0.0, 0.95 * leg * scale, 0.0], "Spine": [0.0, 0.10, 0.01], "Chest": [0.0, 0.11, 0.0],
        "UpperChest": [0.0, 0.12, -0.01], "Neck": [0.0, 0.13, 0.0], "Head": [0.0, 0.09, 0.01],
        "LeftEye": [0.03, 0.07, 0.08], "RightEye": [-0.03, 0.07, 0.08], "Jaw": [0.0, -0.02, 0.04],
    }
    for side, sx in (("Left", 1.0), ("Right", -1.0)):
        arm_dir = np.array([sx * np.cos(down), -np.sin(down), 0.0])
        off.update({
            f"{side}Shoulder": [sx * 0.04, 0.10, 0.0], f"{side}UpperArm": [sx * 0.11, 0.0, 0.0],
            f"{side}LowerArm": (0.28 * arm * arm_dir).tolist(), f"{side}Hand": (0.25 * arm * arm_dir).tolist(),
            f"{side}UpperLeg": [sx * 0.09, -0.06, 0.0], f"{side}LowerLeg": [0.0, -0.42 * leg, 0.0],
            f"{side}Foot": [0.0, -0.40 * leg, -0.01], f"{side}Toes": [0.0, -toe_drop, 0.13],
        })
        for k, finger in enumerate(("Thumb", "Index", "Middle", "Ring", "Little")):
            base = 0.02 * arm_dir + np.array([0.0, 0.0, 0.03 - 0.015 * k])
            off[f"{side}{finger}Proximal"] = (base + 0.06 * arm_dir).tolist()
            off[f"{side}{finger}Intermediate"] = (0.03 * arm_dir).tolist()
            off[f"{side}{finger}Distal"] = (0.02 * arm_dir).tolist()
    parents = {**vmc.UNITY_PARENTS}
    for b in vmc.EXTRA_BONES:
        if "Proximal" in b:
            parents[b] = EXTRA_PARENTS[b]
        elif "Intermediate" in b:
            parents[b] = b.replace("Intermediate", "Proximal")
        elif "Distal" in b:
            parents[b] = b.replace("Distal", "Intermediate")
        else:
            parents[b] = "Head"
    names = list(vmc.UNITY_PARENTS) + list(vmc.EXTRA_BONES)
    names.sort(key=lambda n: _depth(n, parents))
    index = {n: i for i, n in enumerate(names)}
    offsets = np.array([np.asarray(off[n]) * (1.0 if n == "Hips" else scale) for n in names])
    return Skeleton(tuple(names), tuple(-1 if parents[n] is None else index[parents[n]] for n in names),
                    offsets, pelvis=0)


def _depth(name, parents):
    d = 0
    while parents[name] is not None:
        name, d = parents[name], d + 1
    return d


def body_rig(humanoid):
    """The body part of ``humanoid`` (what the retargeter maps)."""
    keep = [i for i, n in enumerate(humanoid.names) if n in vmc.UNITY_PARENTS]
    index = {j: k for k, j in enumerate(keep)}
    return Skeleton(tuple(humanoid.names[i] for i in keep),
                    tuple(-1 if humanoid.parents[i] < 0 else index[humanoid.parents[i]] for i in keep),
                    humanoid.offsets[keep], pelvis=0)


def sender_frames(motion, humanoid, seed=3, root=None):
    """``motion`` (any humanoid skeleton) as the VMC frames a sender driving ``humanoid`` sends:
    body bones retargeted onto its rig (local rotations relative to its A-pose rest), fingers, eyes
    and jaw turning smoothly, blendshapes in [0, 1]. ``root``: (position, rotation xyzw, scale,
    offset) of the Root/Pos message, the hips placed so the avatar stands where it would without."""
    body = body_rig(humanoid)
    on_rig = Retargeter(motion.skeleton, body, find_map(motion.skeleton), MAPS["unity"])(motion)
    rng = np.random.default_rng(seed)
    t = np.arange(motion.n_frames) / motion.fps
    phase = rng.uniform(0, 2 * np.pi, size=(len(vmc.EXTRA_BONES), 3))
    speed = rng.uniform(0.5, 2.0, size=(len(vmc.EXTRA_BONES), 3))
    extra_angles = 0.4 * np.sin(speed[None] * t[:, None, None] + phase[None])
    extra_q = vmc.core_to_unity_rotation(rot.from_euler(extra_angles, "XYZ"))
    blend_phase = rng.uniform(0, 2 * np.pi, size=len(BLENDSHAPES))
    q = vmc.core_to_unity_rotation(on_rig.rotations)
    hips = on_rig.positions[:, 0]
    root_p, root_q, root_s, root_o = (np.zeros(3), np.array([0.0, 0.0, 0.0, 1.0]), None, None) \
        if root is None else root
    if root is not None:
        # The avatar stands at (p - offset): the hips relative to that root.
        world = vmc.unity_to_core_position(root_p - (root_o if root_o is not None else 0.0))
        rq = vmc.unity_to_core_rotation(root_q)
        hips = rot.rotate(rot.conjugate(rq), hips - world)
        q = q.copy()
        q[:, 0] = vmc.core_to_unity_rotation(rot.multiply(rot.conjugate(rq), on_rig.rotations[:, 0]))
    f32 = lambda v: None if v is None else np.asarray(v, dtype=np.float32).astype(np.float64)  # noqa: E731
    root_p, root_q, root_s, root_o = f32(root_p), f32(root_q), f32(root_s), f32(root_o)
    frames = []
    for k in range(motion.n_frames):
        bones = {}
        for j, b in enumerate(body.names):
            p = hips[k] if j == 0 else body.offsets[j]
            bones[b] = (vmc.core_to_unity_position(p).astype(np.float32).astype(np.float64),
                        np.asarray(q[k, j], dtype=np.float32).astype(np.float64))
        for i, b in enumerate(vmc.EXTRA_BONES):
            p = humanoid.offsets[humanoid.names.index(b)]
            bones[b] = (vmc.core_to_unity_position(p).astype(np.float32).astype(np.float64),
                        extra_q[k, i].astype(np.float32).astype(np.float64))
        blend = {name: float(np.float32(0.5 + 0.5 * np.sin(2.0 * t[k] + blend_phase[i])))
                 for i, name in enumerate(BLENDSHAPES)}
        frames.append(vmc.VmcFrame(bones, (root_p, root_q), None, root_s, root_o, blend, True, (1, 3, 0, 1)))
    return frames


def canonical_motion_of(frames, fps):
    """What the bridge's decoder makes of sender frames: canonical motion."""
    return vmc.VmcDecoder(fps=fps)(frames)


def as_motion(frames, fps):
    """Sender frames as a Motion on the sender's own body rig (root folded in), for comparisons."""
    rig = vmc.unity_rig(frames[0])
    return vmc.rig_motion(rig, frames, fps)


__all__ = ["BLENDSHAPES", "Motion", "unity_humanoid", "body_rig", "sender_frames", "as_motion"]
