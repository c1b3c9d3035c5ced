"""Conforming retargeted joint frames: positions untouched, rotations made typical of the training data."""

import numpy as np

from motion_style_ros.core import rotations as rot
from motion_style_ros.core.conform import (
    ANKLES, ARM_JOINTS, CHAINS, ROLL_EVIDENCE, ROLL_MIN_FRAMES, ROLL_SURE_FRAMES, UNROLLED, StreamGround,
    StreamRolls, apply_rolls, arm_moments, arms_hang, clip_rolls, conform_rolls, ground, planted_ankle_height,
    roll_model,
)
from motion_style_ros.core.resample import resample
from motion_style_ros.core.synthetic import KINDS, synthetic_motion
from motion_style_ros.core.retarget import retarget
from motion_style_ros.core.skeleton import canonical
from motion_style_ros.io import bvh, datasets
from motion_style_ros.io.resources import rotation_stats, rotation_stats_file


def typicality(motion, stats) -> float:
    """Mean squared z-score of the rolled arm joints' 6D rotations under the training statistics,
    on the frames where the arms hang (what the statistics describe)."""
    sk = motion.skeleton
    hang = arms_hang(motion.global_positions(), sk)
    scores = []
    for side, chain in enumerate(CHAINS):
        joints = [sk.index(n) for n in chain if n not in UNROLLED]
        q = motion.rotations[hang[:, side]][:, joints]
        scores.append(np.square((rot.to_6d(q) - stats["mean"][joints]) / stats["std"][joints]).mean())
    return float(np.mean(scores))


def test_a_retargeted_cmu_walk_keeps_its_positions_and_gets_typical_arms(datasets):
    stats = rotation_stats()
    source = bvh.read(datasets / "cmu/data/07/07_01.bvh").to_motion()[1:]
    raw = retarget(source, canonical())
    conformed = conform_rolls(raw, stats)
    assert np.abs(conformed.global_positions() - raw.global_positions()).max() < 1e-9
    assert typicality(conformed, stats) < 0.6 * typicality(raw, stats)  # 7.4 vs 13.4 on 07_01
    # Only the arm chains' frames turn, and a hand's own frame does not (only its parent's roll
    # is undone on it).
    hands = [canonical().index(n) for n in UNROLLED]
    assert np.allclose(rot.angle_between(conformed.rotations[:, hands], raw.rotations[:, hands]),
                       rot.angle_between(conformed.rotations[:1, hands], raw.rotations[:1, hands]), atol=0.3)
    arms = {canonical().index(n) for chain in CHAINS for n in chain}
    others = [j for j in range(22) if j not in arms]
    assert np.array_equal(conformed.rotations[:, others], raw.rotations[:, others])


def test_a_bandai_clip_is_nearly_left_as_it_is(datasets):
    stats = rotation_stats()
    path = datasets / "bandai-namco/Bandai-Namco-Research-Motiondataset-2/data/dataset-2_walk_normal_001.bvh"
    clip = datasets_module().load_clip(datasets_module().ClipInfo("bandai-2", path, path.stem, "walk",
                                                                  "normal", "", ""))
    conformed = conform_rolls(clip, stats)
    # A clip of the training data itself is not rolled: the rolled frames would not be typical
    # enough to be worth it (ROLL_EVIDENCE).
    assert np.degrees(rot.angle_between(conformed.rotations, clip.rotations)).max() < 1e-6


def test_grounding_puts_retargeted_cmu_ankles_at_the_training_data_height(datasets):
    stats = rotation_stats()
    assert 0.08 < stats["ankle_height"] < 0.15  # Bandai ankles rest about 12 cm up
    raw = retarget(bvh.read(datasets / "cmu/data/07/07_01.bvh").to_motion()[1:], canonical())
    grounded = ground(conform_rolls(raw, stats), stats)
    assert planted_ankle_height(raw) < stats["ankle_height"] - 0.03  # the CMU feet sink in
    assert abs(planted_ankle_height(grounded) - stats["ankle_height"]) < 1e-9
    # The body moves by one vertical offset, no joint against another (joint_Root, the static
    # origin above the pelvis, stays).
    shift = (grounded.global_positions() - conform_rolls(raw, stats).global_positions())[:, 1:]
    assert np.allclose(shift[..., [0, 2]], 0.0, atol=1e-9) and np.ptp(shift[..., 1]) < 1e-9


def test_stream_grounding_finds_the_offline_offset_of_a_live_cmu_walk(datasets):
    stats = rotation_stats()
    raw = retarget(bvh.read(datasets / "cmu/data/07/07_01.bvh").to_motion()[1:], canonical())
    ankles = raw.global_positions()[:, [raw.skeleton.index(n) for n in ANKLES]]
    offline = planted_ankle_height(raw) - stats["ankle_height"]  # what ground() moves the clip by
    offsets = {}
    for lift in (0.0, 0.1):
        ground = StreamGround(1, raw.fps, stats["ankle_height"])
        ground.start(ankles[:1] + [0.0, lift, 0.0], np.array([True]))
        offsets[lift] = np.array([ground.update(a[None] + [0.0, lift, 0.0])[0] for a in ankles])
    # Within 2 cm of the clip's offset after a second; a floor 10 cm higher, 10 cm more.
    assert np.abs(offsets[0.0][int(raw.fps):] - offline).max() < 0.02, offline
    assert np.allclose(offsets[0.1], offsets[0.0] + 0.1)
    # A stream that starts on the file's calibration T-pose (its ankles 5 cm below the walk's
    # floor) has found the floor as well after a second.
    tpose = retarget(bvh.read(datasets / "cmu/data/07/07_01.bvh").to_motion()[:1], canonical())
    ground = StreamGround(1, raw.fps, stats["ankle_height"])
    ground.start(tpose.global_positions()[:, [raw.skeleton.index(n) for n in ANKLES]], np.array([True]))
    assert ground.offset[0] < offline - 0.03
    late = np.array([ground.update(a[None])[0] for a in ankles])
    assert np.abs(late[int(raw.fps):] - offline).max() < 0.02


def test_the_shipped_statistics_come_from_the_datasets(datasets):
    import os

    os.environ.setdefault("MOTION_STYLE_DATASETS", str(datasets))
    assert rotation_stats_file().read_text() == \
        datasets_module().rotation_stats_json(progress=False)


def datasets_module():
    return datasets


def test_rolls_undo_exactly_and_leave_positions_alone():
    motion = synthetic_motion("walk", 30.0, 2.0)
    joints = [motion.skeleton.index(n) for n in ARM_JOINTS]
    angles = np.radians(np.linspace(-40.0, 40.0, len(joints)))
    rolled = apply_rolls(motion.rotations, joints, angles)
    assert np.degrees(rot.angle_between(rolled, motion.rotations)).max() > 10.0
    back = apply_rolls(rolled, joints, angles, undo=True)
    assert np.abs(rot.angle_between(back, motion.rotations)).max() < 1e-6
    moved = type(motion)(motion.skeleton, rolled, motion.positions, motion.fps)
    assert np.abs(moved.global_positions() - motion.global_positions()).max() < 1e-9


def numpy_solve(model, second, first, count) -> np.ndarray:
    """RollModel.solve as numpy array arithmetic (the compiled kernel's specification): every grid
    pair's cost, the chain's dynamic programme with argmin, the parabola refinement, the evidence."""
    p, n = count.shape[0], len(CHAINS[0])
    moments = np.concatenate([second.reshape(p, 8, 81), first], axis=-1)[..., None]
    c = (model.coefficients @ moments).reshape(p, 8, 5, 5)
    costs = model.basis @ c @ model.basis.T + count[:, :, None, None] * model.constant[None, :, None, None]
    chain = costs.reshape((p * len(CHAINS), n) + costs.shape[2:])
    total, back = chain[:, 0, 0], []
    for k in range(1, n):
        candidates = total[:, :, None] + chain[:, k]
        back.append(np.argmin(candidates, axis=1))
        total = candidates.min(axis=1)
    choice = np.zeros((len(chain), n), dtype=int)
    choice[:, -1] = np.argmin(total, axis=1)
    rows = np.arange(len(chain))
    for k in range(n - 1, 0, -1):
        choice[:, k - 1] = back[k - 1][rows, choice[:, k]]
    offset = np.zeros(choice.shape)
    for k in range(n):
        parent = choice[:, k - 1] if k else np.zeros(len(chain), dtype=int)
        near = []
        for d in (-1, 0, 1):
            b = (choice[:, k] + d) % len(model.angles)
            near.append(chain[rows, k, parent, b] + (chain[rows, k + 1, b, choice[:, k + 1]] if k < n - 1 else 0.0))
        curve = near[0] - 2.0 * near[1] + near[2]
        offset[:, k] = np.clip(0.5 * (near[0] - near[2]) / np.where(curve > 1e-12, curve, np.inf), -0.5, 0.5)
    frames = count[:, ::n].reshape(-1)
    gain = (chain[:, :, 0, 0].sum(axis=1) - total.min(axis=1)) / np.maximum(frames, 1)
    low, high = ROLL_EVIDENCE
    low = np.where(frames >= ROLL_SURE_FRAMES, low, high - 1e-6)
    weight = np.clip((gain - low) / (high - low), 0.0, 1.0) * (frames >= ROLL_MIN_FRAMES)
    rolls = np.angle(np.exp(1j * (model.angles[choice] + offset * model.angles[1])))
    angles = (weight[:, None] * rolls).reshape(p, 8)
    angles[:, [ARM_JOINTS.index(j) for j in UNROLLED]] = 0.0
    return angles


def test_the_compiled_roll_solve_is_the_numpy_dynamic_programme():
    model = roll_model(rotation_stats())
    walk = synthetic_motion("walk", 30.0, 4.0)
    joints = [walk.skeleton.index(n) for n in ARM_JOINTS]
    hang = arms_hang(walk.global_positions(), walk.skeleton)
    moments = []
    for degrees in (0.0, 20.0, 40.0, -35.0):  # rigs rolled as a retargeted CMU arm is, and not
        rolled = apply_rolls(walk.rotations, joints, np.radians(np.linspace(degrees, degrees / 2, 8)), undo=True)
        for frames in (3, 10, 120):  # all or nothing below ROLL_SURE_FRAMES, then the evidence ramp
            moments.append(arm_moments(rolled[:frames], hang[:frames], joints))
    second, first, count = (np.stack(m) for m in zip(*moments))
    solved = model.solve(second, first, count)
    assert np.degrees(np.abs(solved)).max() > 20.0  # the rolled rigs are rolled back
    assert np.abs(solved - numpy_solve(model, second, first, count)).max() < 1e-9


def test_synthetic_performers_are_not_rolled():
    # The demo's performer, waving included: a raised arm says nothing about the rig (arms_hang).
    stats = rotation_stats()
    for kind in KINDS:
        assert np.abs(clip_rolls(synthetic_motion(kind, 30.0, 6.0), stats)).max() < 1e-9, kind
    wave = synthetic_motion("wave", 30.0, 6.0)
    assert not arms_hang(wave.global_positions(), wave.skeleton).all()


def test_a_live_cmu_stream_finds_the_rolls_of_the_whole_clip(datasets):
    stats = rotation_stats()
    raw = resample(retarget(bvh.read(datasets / "cmu/data/07/07_03.bvh").to_motion()[1:], canonical()), 30.0)
    offline = clip_rolls(raw, stats)
    assert np.degrees(offline).min() < -30.0  # the CMU forearm frames are rolled 35-45 degrees
    live = StreamRolls(1, 30.0, stats, raw.skeleton)
    positions = raw.global_positions()
    errors = []
    for t in range(raw.n_frames):
        live.observe(raw.rotations[t:t + 1], positions[t:t + 1])
        errors.append(np.degrees(np.abs(np.angle(np.exp(1j * (live.angles[0] - offline))))).max())
    # Within 10 degrees on every arm joint after a second (8.2 on this clip), 5 after two, and
    # the clip's rolls at its end.
    assert max(errors[30:]) < 10.0 and max(errors[60:]) < 5.0, (max(errors[30:]), max(errors[60:]))
    assert errors[-1] < 1.0
    # A clip that starts afresh starts from no rolls.
    live.clear(slice(None))
    assert not live.angles.any() and not live.frames.any()
