"""Canonical-skeleton poses as sensor_msgs/JointState vectors and back (numpy only, no ROS).

The default layout (:meth:`JointStateLayout.canonical`, written out in ``config/layouts/canonical.yaml``):

* ``root_tx, root_ty, root_tz``: the pelvis (``Hips``) world position in metres, REP-103 axes;
* ``root_rx, root_ry, root_rz``: the pelvis world orientation;
* ``<Bone>_rx, <Bone>_ry, <Bone>_rz`` for every canonical joint below ``Hips`` in skeleton order: the
  joint's rotation relative to its parent.

Frames: the motion core is Y up, facing +Z, left = +X; REP-103 is X forward, Y left, Z up. The proper
rotation ``C`` maps core ``(x, y, z)`` to ROS ``(z, x, y)``; positions map as ``p_ros = C p_core`` and
rotations as ``R_ros = C R_core C^T``. Angles are radians, intrinsic X-Y-Z Euler of ``R_ros``:
``R = Rx(rx) @ Ry(ry) @ Rz(rz)``. The canonical rig's zero pose has every bone along its local X, so a
standing pose has non-zero angles (the T-pose's local rotations); those are what a stream carries.

Other layouts come from a YAML map (see :meth:`JointStateLayout.from_yaml`): each JointState name is
one DOF of the default layout, ``value = scale * default_value + offset``, angles then wrapped to
[-pi, pi). Decoding fills the DOFs a map leaves out from the canonical T-pose; names in a message that
the map lacks are an error unless the map says ``unknown_names: ignore`` (a robot publishes joints a
humanoid map has no use for). Euler angles of the rest pose sit near +-pi for some bones (the legs),
so a consumer that differentiates angles should unwrap them first.

Names that are not body DOFs but belong to the same frame, such as a VMC avatar's fingers, eyes and
jaw (``LeftIndexProximal_rx`` ...: the sender's own local rotations, in the same Euler convention),
ride along: a layout's ``passthrough`` patterns (``fnmatch``; the canonical layout's are
:data:`VMC_PASSTHROUGH`) accept them, decoding skips them, and a node republishes them with the
pose they came with (:class:`FrameDelay`: the stylized output of stamp ``S`` shows the input of
``S - latency``, so its extras are that frame's too).
"""

from __future__ import annotations

import math
import fnmatch
import functools
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numba import njit

from motion_style_ros.core import jit
from motion_style_ros.core.jit import qmul, quat_entries
from motion_style_ros.core.retarget import tpose
from motion_style_ros.core.skeleton import Skeleton, canonical
from motion_style_ros.errors import MotionStyleError
from motion_style_ros.io import files

AXES = ("tx", "ty", "tz", "rx", "ry", "rz")
# Core (x, y, z) -> ROS (z, x, y): row i of C picks the core axis that becomes ROS axis i.
_CORE_TO_ROS = [2, 0, 1]
_PELVIS = canonical().pelvis  # looked up once: building the skeleton costs more than a frame's maths
# Unity HumanBodyBones outside the body the stylizer restyles: fingers, eyes and jaw. A VMC stream's
# values for them travel as <Bone>_rx/_ry/_rz beside the body (see rotation_values).
FINGER_BONES = tuple(f"{side}{finger}{part}" for side in ("Left", "Right")
                     for finger in ("Thumb", "Index", "Middle", "Ring", "Little")
                     for part in ("Proximal", "Intermediate", "Distal"))
FACE_BONES = ("LeftEye", "RightEye", "Jaw")
# (config/layouts/canonical.yaml lists the same patterns.)
VMC_PASSTHROUGH = tuple(f"{p}_r[xyz]" for p in ("*Thumb*", "*Index*", "*Middle*", "*Ring*", "*Little*",
                                               "*Eye", "Jaw"))


def to_ros(v: np.ndarray) -> np.ndarray:
    """Core-frame vectors ``(..., 3)`` (Y up) in REP-103 axes (Z up), e.g. FK positions for RViz."""
    return v[..., _CORE_TO_ROS]


def _rows(x: np.ndarray, width: int) -> np.ndarray:
    """``x (..., width)`` as the kernels' float64 C rows ``(N, width)``."""
    return jit.rows(np.asarray(x, dtype=np.float64).reshape(-1, width))


def rotation_names(bones: Sequence[str]) -> list[str]:
    """``<bone>_rx, _ry, _rz`` for each bone: how extra (pass-through) rotations are named."""
    return [f"{b}_{a}" for b in bones for a in AXES[3:]]


def rotation_values(quats: np.ndarray) -> np.ndarray:
    """Core-frame quaternions ``(N, 4)`` as ``(3 N,)`` angles, the layout's convention (REP-103 axes,
    intrinsic X-Y-Z Euler), e.g. a VMC sender's finger rotations relative to its rest pose."""
    return euler_rows(_rows(quats, 4)).ravel()


def rotations_from_values(values: np.ndarray) -> np.ndarray:
    """The inverse of :func:`rotation_values`: ``(3 N,)`` angles -> core quaternions ``(N, 4)``."""
    return quat_rows(_rows(values, 3))


def default_names(skeleton: Skeleton | None = None) -> list[str]:
    """The default layout's names: root translation and orientation, then 3 angles per ball joint."""
    skeleton = skeleton or canonical()
    bones = skeleton.names[skeleton.pelvis + 1:]
    return [f"root_{a}" for a in AXES] + [f"{b}_{a}" for b in bones for a in AXES[3:]]


@functools.cache
def _tpose_vector() -> np.ndarray:
    skel = canonical()
    return _encode_default(tpose(skel).local_rotations, skel.offsets[skel.pelvis])


def _encode_default(rotations: np.ndarray, root_positions: np.ndarray) -> np.ndarray:
    """``(..., 22, 4)`` local rotations and ``(..., 3)`` pelvis positions -> ``(..., 66)``."""
    rotations = np.asarray(rotations, dtype=np.float64)
    lead, n_joints = rotations.shape[:-2], rotations.shape[-2]
    values = layout_values(_rows(rotations, n_joints * 4).reshape(-1, n_joints, 4),
                                   _rows(root_positions, 3), _PELVIS)
    return values.reshape(lead + values.shape[-1:])


def _decode_default(values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    rotations, roots = layout_poses(_rows(values, values.shape[-1]), _PELVIS)
    lead = values.shape[:-1]
    return rotations.reshape(lead + rotations.shape[1:]), roots.reshape(lead + (3,))


def _finite_number(v) -> bool:
    """Whether ``v`` (from YAML) is an int or float that is finite as a float (not a bool)."""
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        return False
    try:
        return bool(np.isfinite(float(v)))
    except OverflowError:  # an int beyond the floats
        return False


@dataclass(frozen=True)
class _Dof:
    name: str
    index: int  # into the default layout
    scale: float
    offset: float


class JointStateLayout:
    """The order and meaning of JointState ``name``/``position`` entries for the canonical skeleton."""

    def __init__(self, dofs: Sequence[_Dof], ignore_unknown: bool = False, source: str = "layout",
                 passthrough: Sequence[str] = ()):
        self._dofs = tuple(dofs)
        self.passthrough = tuple(passthrough)  # fnmatch patterns of names that ride along
        self.names: list[str] = [d.name for d in self._dofs]
        self.ignore_unknown = ignore_unknown
        self.source = source
        self._index = np.array([d.index for d in self._dofs], dtype=np.intp)
        self._scale = np.array([d.scale for d in self._dofs])
        self._offset = np.array([d.offset for d in self._dofs])
        self.angular = self._index >= 3  # per name: an angle (radians, 2 pi periodic), not metres
        self._by_name = {d.name: i for i, d in enumerate(self._dofs)}
        self._cached: tuple[tuple[str, ...], np.ndarray, np.ndarray] | None = None

    @classmethod
    def canonical(cls) -> "JointStateLayout":
        names = default_names()
        return cls([_Dof(n, i, 1.0, 0.0) for i, n in enumerate(names)], source="canonical layout",
                   passthrough=VMC_PASSTHROUGH)

    def passes(self, name: str) -> bool:
        """Whether ``name`` is no DOF of this layout but one of its pass-through names."""
        return name not in self._by_name and any(fnmatch.fnmatchcase(name, p) for p in self.passthrough)

    @classmethod
    def from_yaml(cls, path: str | Path) -> "JointStateLayout":
        """A layout from a YAML map::

            unknown_names: error        # or ignore; optional, default error
            passthrough: ["*_finger_joint"]   # optional: names that ride along unchanged
            joints:                     # JointState names in publishing order
              - {name: left_knee_joint, dof: LowerLeg_L_rx, scale: -1.0, offset: 0.0}

        ``dof`` is a name of the default layout; ``scale`` (non-zero) and ``offset`` are optional.
        ``passthrough`` lists ``fnmatch`` patterns of names that are accepted beside the joints and
        passed on with the frame they came with (default: none).
        """
        from ruamel.yaml import YAML, YAMLError

        path = Path(path)

        def bad(problem: str) -> MotionStyleError:
            return MotionStyleError(f"{path}: {problem}")

        try:
            data = YAML(typ="safe").load(files.read_bytes(path, "layout").decode("utf-8"))
        except UnicodeDecodeError:
            raise bad("not a text file (a layout is YAML)") from None
        except YAMLError as exc:
            raise bad(f"not valid YAML ({' '.join(str(exc).split())})") from None
        except RecursionError:
            raise bad("not a layout (YAML nested too deeply)") from None
        except ValueError as exc:  # an int of over 4300 digits
            raise bad(f"not a layout ({' '.join(str(exc).split())})") from None
        if not isinstance(data, dict) or not isinstance(data.get("joints"), list) or not data["joints"]:
            raise bad("expected a mapping with a non-empty 'joints' list")
        extra = set(data) - {"joints", "unknown_names", "passthrough"}
        if extra:
            raise bad(f"unknown keys {sorted(map(str, extra))}; allowed: joints, unknown_names, passthrough")
        passthrough = data.get("passthrough", [])
        if not isinstance(passthrough, list) or not all(isinstance(p, str) and p for p in passthrough):
            raise bad("passthrough must be a list of name patterns (fnmatch), e.g. ['*Proximal_r?']")
        unknown = data.get("unknown_names", "error")
        if unknown not in ("error", "ignore"):
            raise bad(f"unknown_names is {unknown!r}; allowed: error, ignore")
        index = {n: i for i, n in enumerate(default_names())}
        dofs, seen = [], set()
        for k, entry in enumerate(data["joints"]):
            where = f"joints[{k}]"
            if not isinstance(entry, dict) or not {"name", "dof"} <= set(entry):
                raise bad(f"{where} needs 'name' and 'dof'")
            if set(entry) - {"name", "dof", "scale", "offset"}:
                raise bad(f"{where} has unknown keys; allowed: name, dof, scale, offset")
            name, dof = str(entry["name"]), entry["dof"]
            if not isinstance(dof, str) or dof not in index:
                raise bad(f"{where} ({name!r}): unknown dof {dof!r:.60}; use a default layout name such "
                          f"as root_tx or UpperArm_L_ry")
            if name in seen:
                raise bad(f"{where}: duplicate name {name!r}")
            seen.add(name)
            scale, offset = entry.get("scale", 1.0), entry.get("offset", 0.0)
            if not all(_finite_number(v) for v in (scale, offset)) or scale == 0:
                raise bad(f"{where} ({name!r}): scale and offset must be finite numbers, scale non-zero")
            dofs.append(_Dof(name, index[dof], float(scale), float(offset)))
        return cls(dofs, ignore_unknown=unknown == "ignore", source=str(path), passthrough=passthrough)

    def encode(self, rotations: np.ndarray, root_positions: np.ndarray) -> np.ndarray:
        """Positions ``(..., len(names))`` from local rotations ``(..., 22, 4)`` and the pelvis
        world position ``(..., 3)`` in the core frame."""
        values = _encode_default(np.asarray(rotations, dtype=np.float64), root_positions)
        out = values[..., self._index] * self._scale + self._offset
        # An offset may push an angle past +-pi; wrap it back (decoding is 2 pi periodic anyway).
        out[..., self.angular] = np.mod(out[..., self.angular] + np.pi, 2 * np.pi) - np.pi
        return out

    def encode_motion(self, motion) -> np.ndarray:
        """``(T, len(names))`` for a canonical-skeleton :class:`Motion`."""
        return self.encode(motion.rotations, motion.root_positions)

    def _permutation(self, names: Sequence[str]) -> tuple[np.ndarray, np.ndarray]:
        key = tuple(names)
        if self._cached is not None and self._cached[0] == key:
            return self._cached[1], self._cached[2]
        if len(set(key)) != len(key):
            dup = sorted({n for n in key if key.count(n) > 1})
            raise MotionStyleError(f"{self.source}: duplicate joint names {dup}")
        unknown = [n for n in key if n not in self._by_name and not self.passes(n)]
        if unknown and not self.ignore_unknown:
            raise MotionStyleError(f"{self.source}: unknown joint names {unknown[:5]}"
                                   f"{' ...' if len(unknown) > 5 else ''}; expected {self.names[:3]} ...")
        missing = sorted(set(self.names) - set(key), key=self._by_name.get)
        if missing:
            raise MotionStyleError(f"{self.source}: missing joint names {missing[:5]}"
                                   f"{' ...' if len(missing) > 5 else ''}")
        src = np.array([i for i, n in enumerate(key) if n in self._by_name], dtype=np.intp)
        dst = np.array([self._by_name[key[i]] for i in src], dtype=np.intp)
        self._cached = (key, src, dst)
        return src, dst

    def angles(self, names: Sequence[str], positions: np.ndarray) -> tuple[np.ndarray, list[str]]:
        """The message's angle channels (radians, after scale and offset) with their names, for
        plausibility checks; names as for :meth:`decode`."""
        src, dst = self._permutation(names)
        mine = self.angular[dst]
        values = (np.asarray(positions, dtype=np.float64)[src[mine]] - self._offset[dst[mine]]) / self._scale[dst[mine]]
        return values, [names[i] for i in src[mine]]

    def decode(self, names: Sequence[str],
               positions: Sequence[float]) -> tuple[np.ndarray, np.ndarray]:
        """Local rotations ``(22, 4)`` (``joint_Root`` identity, ``Hips`` the pelvis world orientation)
        and the pelvis position ``(3,)`` in the core frame, from one JointState's name/position."""
        values = np.asarray(positions, dtype=np.float64)
        if values.ndim != 1 or len(names) != values.shape[0]:
            raise MotionStyleError(f"{self.source}: {len(names)} names but {values.size} positions")
        if not np.isfinite(values).all():
            bad = [names[i] for i in np.flatnonzero(~np.isfinite(values))[:5]]
            raise MotionStyleError(f"{self.source}: non-finite positions for {bad}")
        src, dst = self._permutation(names)
        ordered = np.empty(len(self.names))
        ordered[dst] = values[src]
        full = _tpose_vector().copy()
        full[self._index] = (ordered - self._offset) / self._scale
        return _decode_default(full)


class FrameDelay:
    """Values that belong to a stream's frames (pass-through names), looked up by stamp.

    A stylized output stamped ``S`` shows the input of ``S - latency``; :meth:`at` gives the values
    pushed with the frame whose stamp is nearest that moment (the older one on a tie, never one
    pushed after ``S``), so what rides beside the pose stays in step with it. A stamp more than
    ``gap_seconds`` after the previous one, or not after it, starts afresh (as a session does).
    """

    def __init__(self, gap_seconds: float, keep: int = 512) -> None:
        self.gap_ns = round(gap_seconds * 1e9)
        self._frames: deque[tuple[int, np.ndarray]] = deque(maxlen=keep)

    def clear(self) -> None:
        self._frames.clear()

    def push(self, stamp_ns: int, values: np.ndarray) -> None:
        if self._frames and not 0 < stamp_ns - self._frames[-1][0] <= self.gap_ns:
            self._frames.clear()
        self._frames.append((stamp_ns, np.asarray(values)))

    def at(self, stamp_ns: int) -> np.ndarray:
        """The values of the frame nearest ``stamp_ns``; raises IndexError before any push."""
        best = None
        for stamp, values in reversed(self._frames):
            if best is not None and abs(stamp - stamp_ns) > abs(best[0] - stamp_ns):
                break  # stamps only fall from here: the nearest one is behind us
            best = (stamp, values)
        if best is None:
            raise IndexError("no frame pushed")
        return best[1]


@njit(cache=True)
def _ros_euler(q, out, at) -> None:
    """Intrinsic X-Y-Z Euler angles (``rotations.to_euler(q, "XYZ")``) of the core quaternion
    ``q`` turned into REP-103 axes, into ``out[at:at + 3]``."""
    ros = np.empty(4)
    ros[0], ros[1], ros[2], ros[3] = q[0], q[3], q[1], q[2]
    m00, m01, m02, _, m11, m12, _, m21, m22 = quat_entries(ros)
    cos_b = math.hypot(m00, m01)
    out[at + 1] = math.atan2(m02, cos_b)
    if cos_b < 1e-7:  # gimbal lock: the third angle 0, the first takes the whole turn
        out[at], out[at + 2] = math.atan2(m21, m11), 0.0
    else:
        out[at], out[at + 2] = math.atan2(-m12, m22), math.atan2(-m01, m00)


@njit(cache=True)
def _ros_quat(angles, at, q) -> None:
    """The inverse of :func:`_ros_euler`: ``Rx @ Ry @ Rz`` of ``angles[at:at + 3]`` as a core
    quaternion ``q``."""
    ca, sa = math.cos(0.5 * angles[at]), math.sin(0.5 * angles[at])
    cb, sb = math.cos(0.5 * angles[at + 1]), math.sin(0.5 * angles[at + 1])
    cc, sc = math.cos(0.5 * angles[at + 2]), math.sin(0.5 * angles[at + 2])
    w, x, y, z = ca * cb, sa * cb, ca * sb, sa * sb  # Rx @ Ry, then @ Rz:
    rw, rx, ry, rz = w * cc - z * sc, x * cc + y * sc, y * cc - x * sc, z * cc + w * sc
    q[0], q[1], q[2], q[3] = rw, ry, rz, rx


@njit(cache=True)
def euler_rows(quats):
    """:func:`_ros_euler` of every row of ``quats (N, 4)``: ``(N, 3)``."""
    out = np.empty((quats.shape[0], 3))
    for r in range(quats.shape[0]):
        _ros_euler(quats[r], out[r], 0)
    return out


@njit(cache=True)
def quat_rows(angles):
    """:func:`_ros_quat` of every row of ``angles (N, 3)``: ``(N, 4)``."""
    out = np.empty((angles.shape[0], 4))
    for r in range(angles.shape[0]):
        _ros_quat(angles[r], 0, out[r])
    return out


@njit(cache=True)
def layout_values(rotations, roots, pelvis):
    """The default JointState layout of poses (rows of ``rotations (F, J, 4)``, ``roots (F, 3)``):
    the pelvis position in REP-103 axes, its world orientation (the static root's rotation times
    the pelvis's), then every joint below it, three angles each: ``(F, 3 + 3 (J - pelvis))``."""
    n_joints = rotations.shape[1]
    out = np.empty((rotations.shape[0], 3 + 3 * (n_joints - pelvis)))
    hips = np.empty(4)
    for f in range(rotations.shape[0]):
        out[f, 0], out[f, 1], out[f, 2] = roots[f, 2], roots[f, 0], roots[f, 1]
        qmul(rotations[f, 0], rotations[f, pelvis], hips)
        _ros_euler(hips, out[f], 3)
        for j in range(pelvis + 1, n_joints):
            _ros_euler(rotations[f, j], out[f], 3 + 3 * (j - pelvis))
    return out


@njit(cache=True)
def layout_poses(values, pelvis):
    """The inverse of :func:`layout_values`: local rotations ``(F, J, 4)`` (the joints above the
    pelvis identity, the pelvis its world orientation) and roots ``(F, 3)``."""
    n_joints = pelvis + (values.shape[1] - 3) // 3
    rotations = np.zeros((values.shape[0], n_joints, 4))
    roots = np.empty((values.shape[0], 3))
    for f in range(values.shape[0]):
        roots[f, 0], roots[f, 1], roots[f, 2] = values[f, 1], values[f, 2], values[f, 0]
        for j in range(pelvis):
            rotations[f, j, 0] = 1.0
        for j in range(pelvis, n_joints):
            _ros_quat(values[f], 3 + 3 * (j - pelvis), rotations[f, j])
    return rotations, roots
