"""What ``vmc_bridge`` does with VMC (no ROS here): frames in -> canonical JointStates (the fingers,
eyes and jaw as names of their own, the blendshapes apart), and stylized JointStates back out on the
sender's own rig, with everything the stylizer does not restyle sent as it came."""

from __future__ import annotations

import threading
from collections import Counter, deque
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from motion_style_ros.core import rotations as rot
from motion_style_ros.core.motion import Motion
from motion_style_ros.core.retarget import Retargeter
from motion_style_ros.core.skeleton import canonical
from motion_style_ros.errors import MotionStyleError
from motion_style_ros.io.joint_state import JointStateLayout, rotation_names, rotation_values, rotations_from_values
from motion_style_ros.io.vmc.osc import Packet, bone_message, build_message, bundle, frame_bundle, transform_args
from motion_style_ros.io.vmc.protocol import (
    APPLY_ADDRESS,
    BLEND_ADDRESS,
    CALIBRATED,
    EXTRA_BONES,
    MAX_VALUE,
    OK_ADDRESS,
    ROOT_ADDRESS,
    TIME_ADDRESS,
    VmcFrame,
    core_to_unity_position,
    core_to_unity_rotation,
    unity_to_core_rotation,
    usable,
)
from motion_style_ros.io.vmc.rig import VmcDecoder, VmcEncoder, rig_motion, root_transform

STALE_NS = 100_000_000  # an output whose frame is further than this from every kept one: counted


@dataclass(frozen=True)
class _Received:
    """What the link published for one frame, kept to send the frame's stylized pose back."""

    stamp_ns: int
    frame: VmcFrame
    retarget: Retargeter  # sender rig -> canonical, as used for this frame
    canonical_rotations: np.ndarray  # (22, 4) global, core frame
    canonical_hips: np.ndarray  # (3,) hip centre
    rig_rotations: np.ndarray  # (J, 4) the sender rig's global rotations, root folded in
    rig_local: np.ndarray  # (J, 4) its local rotations (the root folded into the hips)
    rig_hips: np.ndarray  # (3,) its hip centre
    rig_pelvis: np.ndarray  # (3,) its Hips joint
    extras: dict[str, np.ndarray]  # pass-through bone -> the 3 JointState values published for it


def _hip_centre(positions: np.ndarray, joints: dict[str, int]) -> np.ndarray:
    return 0.5 * (positions[joints["UpperLeg_L"]] + positions[joints["UpperLeg_R"]])


class VmcLink:
    """VMC frames -> canonical JointState values, and stylized ones back to VMC on the sender's rig.

    :meth:`receive` converts a frame (:class:`VmcDecoder`) and keeps it with the stamp it was
    published under. :meth:`send` takes a stylized JointState, picks the kept frame whose pose that
    output shows (stamp nearest ``stamp - delay``, the stylizer's latency), and sends the stylized
    pose as a change of that frame: each body bone mapped to a canonical joint turns in the world
    as the canonical joint turned (stylized global times input global inverse), the sender's other
    body bones (e.g. Chest between Spine and UpperChest) keep their local rotations, the hip
    centre moves as the canonical one did (over the leg-length ratio), and bone local positions,
    the root transform (with its scale and offset), fingers, eyes, jaw, blendshapes, OK and every
    pass-through message are that frame's, as they came. So a stylizer that changes nothing
    returns the sender's frame (to float32), and a stylized pose keeps the sender's rest pose and
    proportions. A finger, eye or jaw whose JointState values come back changed (a node between
    changed them) goes out as they came back. ``/VMC/Ext/T`` goes out as the time given to
    :meth:`send`. Before any frame was
    received, stylized states go out on a T-posed rig of canonical proportions (:class:`VmcEncoder`).
    """

    def __init__(self, keep_seconds: float = 2.0) -> None:
        self.layout = JointStateLayout.canonical()
        self.decoder = VmcDecoder()
        self.counts: Counter[str] = Counter()
        self.keep_ns = round(keep_seconds * 1e9)
        self._received: deque[_Received] = deque()
        self._lock = threading.Lock()
        self._calibration: int | None = None
        self._fallback: VmcEncoder | None = None
        self._names: dict[tuple[str, ...], list[str]] = {}

    def reset(self) -> None:
        """Forget the rig and the kept frames (the next frame builds the rig again)."""
        self.decoder.reset()
        with self._lock:
            self._received.clear()

    def receive(self, frame: VmcFrame, stamp_ns: int) -> tuple[list[str], np.ndarray] | None:
        """The JointState names and values for ``frame``, or None when its OK state says the pose
        is not the performer's (counted by reason). Raises MotionStyleError when no rig can be
        built or the values are not finite (the rig is then built anew from the next frame)."""
        reason = usable(frame)
        calibration = frame.ok[1] if frame.ok is not None and len(frame.ok) >= 2 else None
        if calibration != self._calibration:
            if calibration == CALIBRATED and self._calibration is not None:
                self.decoder.reset()  # a new calibration: rest pose and proportions may differ
            self._calibration = calibration
        if reason:
            self.counts[reason] += 1
            return None
        try:
            motion = self.decoder([frame])
            values = self.layout.encode(motion.rotations[0], motion.root_positions[0])
            extras = tuple(b for b in EXTRA_BONES if b in frame.bones)
            if extras:
                quats = unity_to_core_rotation(np.stack([frame.bones[b][1] for b in extras]))
                values = np.concatenate([values, rotation_values(quats)])
            if not np.isfinite(values).all():
                raise MotionStyleError("VMC frame gave non-finite joint values")
        except MotionStyleError:
            self.decoder.reset()
            raise
        retarget = self.decoder.retarget
        canon_rot, canon_pos = motion.global_transforms()
        rig = self.decoder.rig
        rig_m = rig_motion(rig, [frame], self.decoder.fps)
        rig_rot, rig_pos = rig_m.global_transforms()
        kept = _Received(stamp_ns, frame, retarget, canon_rot[0],
                         _hip_centre(canon_pos[0], retarget.target_tpose.joints), rig_rot[0],
                         rig_m.rotations[0],
                         _hip_centre(rig_pos[0], retarget.source_tpose.joints), rig_pos[0, 0],
                         {b: values[len(values) - 3 * len(extras) + 3 * i:][:3]
                          for i, b in enumerate(extras)})
        with self._lock:
            self._received.append(kept)
            while stamp_ns - self._received[0].stamp_ns > self.keep_ns or \
                    stamp_ns < self._received[0].stamp_ns:
                self._received.popleft()
        if extras not in self._names:
            self._names[extras] = self.layout.names + rotation_names(extras)
        return self._names[extras], values

    @staticmethod
    def blendshapes(frame: VmcFrame) -> tuple[list[str], np.ndarray]:
        """The frame's blendshape names and values (its Val messages), as received."""
        return list(frame.blendshapes), np.array(list(frame.blendshapes.values()), dtype=np.float64)

    def _shown(self, stamp_ns: int) -> _Received | None:
        with self._lock:
            if not self._received:
                return None
            # The nearest frame, the older one on a tie (as FrameDelay picks pass-through names).
            return min(self._received, key=lambda r: abs(r.stamp_ns - stamp_ns))

    def send(self, names: Sequence[str], positions: Sequence[float], stamp_ns: int,
             delay_ns: int, time: float) -> Packet:
        """The VMC bundle for one stylized JointState stamped ``stamp_ns`` whose pose shows the
        input of ``stamp_ns - delay_ns``. Raises MotionStyleError for names or values the layout
        cannot decode, and for values beyond ``MAX_VALUE`` (no pose has them; past float32's range
        they could not even be sent)."""
        rotations, root = self.layout.decode(names, positions)
        if np.abs(np.asarray(positions, dtype=np.float64)).max() > MAX_VALUE:
            raise MotionStyleError(f"JointState values beyond {MAX_VALUE:g} (m or rad): not a pose")
        shown = self._shown(stamp_ns - delay_ns)
        if shown is None:
            self._fallback = self._fallback or VmcEncoder()
            motion = Motion.from_rotations(canonical(), rotations[None], root[None], 30.0)
            return frame_bundle(self._fallback(motion)[0], time)
        if abs(shown.stamp_ns - (stamp_ns - delay_ns)) > STALE_NS:
            self.counts["sent_stale_frame"] += 1
        where = {n: i for i, n in enumerate(names)}
        extras = {b: np.asarray([positions[where[n]] for n in rotation_names([b])], dtype=np.float64)
                  for b in shown.extras if all(n in where for n in rotation_names([b]))}
        return self._bundle(shown, rotations, root, time, extras)

    def _bundle(self, shown: _Received, rotations: np.ndarray, root: np.ndarray, time: float,
                extras: dict[str, np.ndarray] | None = None) -> Packet:
        """``extras``: pass-through bones' JointState values as they came back; one that differs
        from what was published for the frame (a node changed it on the way) is sent as it came
        back, the others as the sender sent them."""
        ret, frame = shown.retarget, shown.frame
        rig = ret.source
        out = Motion.from_rotations(canonical(), rotations[None], root[None], 30.0)
        out_rot, out_pos = (a[0] for a in out.global_transforms())
        canon_j, rig_j = ret.target_tpose.joints, ret.source_tpose.joints
        turn = {rig_j[c]: rot.multiply(out_rot[canon_j[c]],
                                       rot.conjugate(shown.canonical_rotations[canon_j[c]]))
                for c in ret.common}
        g = np.empty_like(shown.rig_rotations)
        for j, p in enumerate(rig.parents):
            if j in turn:
                g[j] = rot.multiply(turn[j], shown.rig_rotations[j])
            else:
                g[j] = shown.rig_rotations[j] if p < 0 else rot.multiply(g[p], shown.rig_local[j])
        hips = shown.rig_hips + (_hip_centre(out_pos, canon_j) - shown.canonical_hips) / ret.scale
        pelvis = hips - rot.rotate(g[0], rot.rotate(rot.conjugate(shown.rig_rotations[0]),
                                                    shown.rig_hips - shown.rig_pelvis))
        root_p, root_q = root_transform(frame)
        local = np.empty_like(g)
        local[0] = rot.multiply(rot.conjugate(root_q), g[0])
        for j in range(1, rig.n_joints):
            local[j] = rot.multiply(rot.conjugate(g[rig.parents[j]]), g[j])
        local_q = core_to_unity_rotation(rot.normalize(local))
        hips_p = core_to_unity_position(rot.rotate(rot.conjugate(root_q), pelvis - root_p))
        messages = [frame.raw.get("root") or build_message(ROOT_ADDRESS, transform_args("root", *frame.root))]
        for j, b in enumerate(rig.names):
            messages.append(bone_message(b, hips_p if j == 0 else frame.bones[b][0], local_q[j]))
        for b in EXTRA_BONES:
            if b not in frame.bones:
                continue
            back = (extras or {}).get(b)
            if back is not None and not np.array_equal(back, shown.extras[b]) and np.isfinite(back).all():
                q = core_to_unity_rotation(rotations_from_values(back)[0])
                messages.append(bone_message(b, frame.bones[b][0], q))
            else:
                messages.append(frame.raw.get(b) or bone_message(b, *frame.bones[b]))
        if frame.passthrough:
            messages += list(frame.passthrough)
        else:  # a frame made, not received
            messages += [build_message(BLEND_ADDRESS, [k, float(v)]) for k, v in frame.blendshapes.items()]
            messages += [build_message(APPLY_ADDRESS, [])] if frame.apply else []
        messages.append(frame.raw.get("ok") or build_message(OK_ADDRESS, [1]))
        messages.append(build_message(TIME_ADDRESS, [float(time)]))
        return bundle(messages)
