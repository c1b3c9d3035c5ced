"""The canonical skeleton's URDF: the installed file is the generator's, and its forward kinematics
(by yourdfpy, from the URDF text) equals the package's own on real clips."""

from pathlib import Path

import numpy as np
import pytest
import yourdfpy

from motion_style_ros.core.motion import forward_kinematics
from motion_style_ros.core.skeleton import canonical
from motion_style_ros.evaluation.unseen import neutral_clips
from motion_style_ros.io.datasets import index_bandai, load_bandai
from motion_style_ros.io.description import ROOT_LINK, canonical_urdf
from motion_style_ros.io.joint_state import JointStateLayout, to_ros

URDF = Path(__file__).resolve().parents[1] / "urdf" / "canonical_skeleton.urdf"


def test_the_committed_urdf_is_the_generators():
    assert URDF.read_text() == canonical_urdf(), "regenerate: motion-style description --out urdf/canonical_skeleton.urdf"


@pytest.fixture(scope="module")
def clips(datasets):
    bandai = [m for _, m in load_bandai([i for i in index_bandai(datasets, datasets=(2,))
                                         if i.split == "test"][:2], progress=False)]
    return bandai + [m for _, m in neutral_clips(datasets)[::8]]


def test_urdf_forward_kinematics_equals_the_packages_on_real_clips(clips):
    robot = yourdfpy.URDF.load(str(URDF), load_meshes=False, build_collision_scene_graph=False,
                               load_collision_meshes=False)
    layout = JointStateLayout.canonical()
    assert sorted(robot.actuated_joint_names) == sorted(layout.names)
    sk = canonical()
    worst = 0.0
    for motion in clips:
        frames = np.linspace(0, motion.n_frames - 1, 12).astype(int)
        values = layout.encode(motion.rotations[frames], motion.root_positions[frames])
        offsets = np.repeat(sk.offsets[None], len(frames), axis=0)
        offsets[:, sk.pelvis] = motion.root_positions[frames]
        expected = to_ros(forward_kinematics(sk, motion.rotations[frames], offsets)[1])
        for k, frame in enumerate(values):
            robot.update_cfg(dict(zip(layout.names, frame)))
            got = np.array([robot.get_transform(name, ROOT_LINK)[:3, 3] for name in sk.names[sk.pelvis:]])
            worst = max(worst, float(np.abs(got - expected[k, sk.pelvis:]).max()))
    print(f"URDF vs package FK: {worst:.2e} m over {len(clips)} clips")
    assert worst < 1e-6
