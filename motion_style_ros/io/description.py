"""A URDF robot description of the canonical skeleton, so that ``robot_state_publisher`` and RViz's
RobotModel display show a stylized JointState as it is (``urdf/canonical_skeleton.urdf``, made by
``motion-style description``).

The joints are the canonical layout's channels, with the same names and meaning
(:mod:`motion_style_ros.io.joint_state`): ``root_tx/ty/tz`` are prismatic joints along the world's
REP-103 axes, and ``root_rx/ry/rz`` then every bone's ``<bone>_rx/ry/rz`` are revolute joints about
X, then Y, then Z of the frame before (the layout's intrinsic X-Y-Z Euler angles). Each bone's
origin is its skeleton offset in REP-103 axes. Each link of a joint of the skeleton (``Hips``,
``Spine``, ...) has that joint's frame and position, so TF shows the package's own forward
kinematics (``test/test_description.py`` compares them on real clips). Thin cylinders from each
joint to its children make the bones visible.
"""

from __future__ import annotations

from xml.etree import ElementTree as ET

import numpy as np

from motion_style_ros.core.skeleton import Skeleton, canonical
from motion_style_ros.io.joint_state import AXES, to_ros

ROOT_LINK = "world"
ROOT_RANGE = 1e5  # m: the prismatic root joints' limits (the stylizer's max_root_distance)
BONE_RADIUS = 0.015  # m
_AXIS = {"x": "1 0 0", "y": "0 1 0", "z": "0 0 1"}


def _f(values) -> str:
    return " ".join(f"{v:.9g}" for v in np.asarray(values, dtype=float).ravel())


def _joint(robot: ET.Element, name: str, kind: str, parent: str, child: str, axis: str,
           origin=(0.0, 0.0, 0.0)) -> None:
    joint = ET.SubElement(robot, "joint", name=name, type=kind)
    ET.SubElement(joint, "origin", xyz=_f(origin), rpy="0 0 0")
    ET.SubElement(joint, "parent", link=parent)
    ET.SubElement(joint, "child", link=child)
    ET.SubElement(joint, "axis", xyz=_AXIS[axis])
    if kind == "prismatic":
        ET.SubElement(joint, "limit", lower=_f([-ROOT_RANGE]), upper=_f([ROOT_RANGE]), effort="0",
                      velocity="100")


def _bone_visual(link: ET.Element, offset: np.ndarray) -> None:
    """A cylinder from the link's origin to ``offset`` (its child joint, in the link's frame)."""
    length = float(np.linalg.norm(offset))
    if length < 1e-6:
        return
    d = offset / length
    # URDF cylinders lie along Z: turn Z onto d (pitch about Y, then yaw about Z)
    pitch, yaw = np.arccos(np.clip(d[2], -1.0, 1.0)), np.arctan2(d[1], d[0])
    visual = ET.SubElement(link, "visual")
    ET.SubElement(visual, "origin", xyz=_f(offset / 2), rpy=_f([0.0, pitch, yaw]))
    geometry = ET.SubElement(visual, "geometry")
    ET.SubElement(geometry, "cylinder", radius=_f([BONE_RADIUS]), length=_f([length]))
    ET.SubElement(visual, "material", name="bone")


def canonical_urdf(skeleton: Skeleton | None = None) -> str:
    """The URDF text (see the module docstring)."""
    sk = skeleton or canonical()
    robot = ET.Element("robot", name="motion_style_canonical_skeleton")
    material = ET.SubElement(robot, "material", name="bone")
    ET.SubElement(material, "color", rgba="0.95 0.45 0.1 1")
    links = [ROOT_LINK]
    chain = [(f"root_{a}", "prismatic" if a.startswith("t") else "revolute", a[1]) for a in AXES]
    parent = ROOT_LINK
    for k, (name, kind, axis) in enumerate(chain):
        child = sk.names[sk.pelvis] if k == len(chain) - 1 else f"{name}_link"
        _joint(robot, name, "continuous" if kind == "revolute" else kind, parent, child, axis)
        links.append(child)
        parent = child
    for j in range(sk.pelvis + 1, sk.n_joints):
        bone, parent = sk.names[j], sk.names[sk.parents[j]]
        for k, axis in enumerate("xyz"):
            child = bone if axis == "z" else f"{bone}_r{axis}_link"
            origin = to_ros(sk.offsets[j]) if k == 0 else (0.0, 0.0, 0.0)
            _joint(robot, f"{bone}_r{axis}", "continuous", parent, child, axis, origin)
            links.append(child)
            parent = child
    children: dict[str, list[np.ndarray]] = {}
    for j in range(sk.pelvis + 1, sk.n_joints):
        children.setdefault(sk.names[sk.parents[j]], []).append(to_ros(sk.offsets[j]))
    for name in links:
        link = ET.Element("link", name=name)
        for offset in children.get(name, []):
            _bone_visual(link, offset)
        robot.insert(1 + links.index(name), link)
    ET.indent(robot)
    return '<?xml version="1.0"?>\n' + ET.tostring(robot, encoding="unicode") + "\n"
