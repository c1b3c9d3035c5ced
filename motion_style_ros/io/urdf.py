"""Read a robot's kinematics from a URDF file (yourdfpy) into plain numpy data.

Only what a motion target needs is kept: the joints (type, parent and child link, origin, axis,
position and velocity limits), each link's centre of mass, and sample points of each link's
primitive collision shapes (boxes, spheres, cylinders; visual ones for links without collision
shapes), which say where a foot's sole is. Meshes are never loaded: the kinematics are all in the
URDF text, and the robot descriptions this package is tested with ship without meshes.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from motion_style_ros.errors import MotionStyleError
from motion_style_ros.io import files

MOVING = ("revolute", "continuous", "prismatic")
KINDS = (*MOVING, "fixed", "floating", "planar")
MAX_LENGTH = 1e6  # m: no robot's origin, shape or centre of mass is this far out; a corrupt file's are


@dataclass
class UrdfJoint:
    name: str
    kind: str  # URDF joint type
    parent: str
    child: str
    origin: np.ndarray  # (4, 4) child frame in the parent link's at q = 0
    axis: np.ndarray  # (3,) in the joint frame
    lower: float
    upper: float
    velocity: float  # rad/s (m/s for prismatic); inf when the URDF gives none
    mimic: bool = False


@dataclass
class RobotModel:
    """A robot's kinematics as read from a URDF (:func:`motion_style_ros.io.urdf.read`)."""

    name: str
    source: str
    links: list[str]
    joints: list[UrdfJoint]
    coms: dict[str, np.ndarray] = field(default_factory=dict)  # link -> centre of mass (link frame)
    shapes: dict[str, np.ndarray] = field(default_factory=dict)  # link -> (N, 3) shape points


def _shape_points(geometry, origin: np.ndarray) -> np.ndarray | None:
    """Points on a primitive shape's surface (its corners / extreme points), in the link frame."""
    if geometry is None:
        return None
    if geometry.box is not None:
        half = np.asarray(geometry.box.size, dtype=np.float64).reshape(-1) / 2.0
        if half.shape != (3,):
            raise MotionStyleError(f"a box of {half.size} sizes; a box has 3")
        signs = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], dtype=np.float64)
        local = signs * half
    elif geometry.sphere is not None:
        r = float(geometry.sphere.radius)
        local = np.vstack([np.eye(3) * r, -np.eye(3) * r])
    elif geometry.cylinder is not None:
        r, h = float(geometry.cylinder.radius), float(geometry.cylinder.length)
        a = np.linspace(0.0, 2 * np.pi, 8, endpoint=False)
        ring = np.stack([r * np.cos(a), r * np.sin(a), np.zeros_like(a)], axis=-1)
        local = np.vstack([ring + [0, 0, h / 2], ring - [0, 0, h / 2]])
    else:  # meshes (not loaded) and capsules: no points
        return None
    return local @ origin[:3, :3].T + origin[:3, 3]


def read(path: str | Path) -> RobotModel:
    """The kinematics of the URDF at ``path``; a missing or unreadable file is a one-line
    :class:`MotionStyleError`."""
    import yourdfpy

    path = Path(path)
    if not path.exists():
        raise MotionStyleError(f"{path}: no such URDF file")
    files.check(path, "urdf")
    log = logging.getLogger("yourdfpy")
    level = log.level
    log.setLevel(logging.CRITICAL)  # it logs a parse error as it retries; the one it raises is ours
    try:
        urdf = yourdfpy.URDF.load(str(path), load_meshes=False, build_scene_graph=False,
                                  build_collision_scene_graph=False, load_collision_meshes=False)
    except Exception as exc:  # lxml / yourdfpy raise many kinds on a bad file
        problem = " ".join(str(exc).split()) or type(exc).__name__
        raise MotionStyleError(f"{path}: not a readable URDF ({problem[:200]})") from None
    finally:
        log.setLevel(level)
    robot = urdf.robot
    if robot is None or not robot.links:
        raise MotionStyleError(f"{path}: the URDF has no links")

    def finite(what: str, value, shape: tuple[int, ...] | None = None) -> np.ndarray:
        # yourdfpy takes any float (NaN, 1e400, an rpy whose sine is NaN) and any count of them
        array = np.asarray(value, dtype=np.float64)
        if shape is not None and array.shape != shape:
            raise MotionStyleError(f"{path}: {what} has {array.size} values; {np.prod(shape)} expected")
        if not (np.abs(array) < MAX_LENGTH).all():
            raise MotionStyleError(f"{path}: {what} is not finite and within +-{MAX_LENGTH:g} "
                                   f"({' '.join(str(array.tolist()).split())[:80]})")
        return array

    joints = []
    for j in robot.joints:
        if j.type not in KINDS:
            raise MotionStyleError(f"{path}: joint {j.name!r} has type {j.type!r}; URDF's are "
                                   f"{', '.join(KINDS)}")
        limit = j.limit
        lower = -np.inf if limit is None or limit.lower is None else float(limit.lower)
        upper = np.inf if limit is None or limit.upper is None else float(limit.upper)
        if j.type == "continuous" or (j.type == "revolute" and lower == upper == 0.0 and limit is None):
            lower, upper = -np.inf, np.inf
        velocity = np.inf if limit is None or not limit.velocity else float(limit.velocity)
        if np.isnan(lower) or np.isnan(upper) or lower > upper or not velocity > 0:  # NaN too
            raise MotionStyleError(f"{path}: joint {j.name!r} has limits lower {lower:g}, upper "
                                   f"{upper:g}, velocity {velocity:g}: lower <= upper and a positive "
                                   "velocity are needed")
        axis = (np.array([1.0, 0.0, 0.0]) if j.axis is None
                else finite(f"joint {j.name!r}'s axis", j.axis, (3,)))
        if j.type in MOVING and not np.linalg.norm(axis) > 0:  # a fixed joint's axis is unused
            raise MotionStyleError(f"{path}: {j.type} joint {j.name!r} has a zero axis")
        origin = np.eye(4) if j.origin is None else finite(f"joint {j.name!r}'s origin", j.origin, (4, 4))
        joints.append(UrdfJoint(j.name, j.type, j.parent, j.child, origin, axis, lower, upper,
                                velocity, j.mimic is not None))
    coms, shapes = {}, {}
    for link in robot.links:
        if link.inertial is not None and link.inertial.origin is not None:
            coms[link.name] = finite(f"link {link.name!r}'s centre of mass", link.inertial.origin,
                                     (4, 4))[:3, 3].copy()
        for parts in (link.collisions or [], link.visuals or []):  # visual shapes if no collision ones
            try:
                points = [_shape_points(part.geometry, np.eye(4) if part.origin is None
                                        else np.asarray(part.origin, dtype=np.float64)) for part in parts]
            except MotionStyleError as exc:
                raise MotionStyleError(f"{path}: link {link.name!r}: {exc}") from None
            points = [p for p in points if p is not None]
            if points:
                shapes[link.name] = finite(f"link {link.name!r}'s shapes", np.vstack(points))
                break
    return RobotModel(robot.name or path.stem, str(path), [link.name for link in robot.links],
                      joints, coms, shapes)
