"""Topic names and JointState messages as every node builds them."""

from __future__ import annotations

import array
from collections.abc import Sequence

import numpy as np
from sensor_msgs.msg import JointState


def prefixed(prefix: str, name: str) -> str:
    """A performer's topic: ``name`` under its ``prefix`` (``''``: the node's namespace)."""
    return f"{prefix.rstrip('/')}/{name}" if prefix else name


def joint_state(names: Sequence[str], positions: np.ndarray, stamp, frame_id: str = "") -> JointState:
    msg = JointState(name=list(names), position=doubles(positions))
    msg.header.stamp = stamp
    msg.header.frame_id = frame_id
    return msg


def doubles(values: np.ndarray) -> array.array:
    """A float64 sequence field's value: an ``array('d')`` is taken as it is, where a list is
    checked element by element (3.7 against 5.4-9.9 us for a 66-joint JointState here)."""
    return array.array("d", np.ascontiguousarray(values, dtype=np.float64).tobytes())
