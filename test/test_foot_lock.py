"""Foot locking on real walks: planted feet stop sliding, nothing else moves, bones keep their lengths."""

import numpy as np
import pytest

from motion_style_ros.core import rotations as rot
from motion_style_ros.core.foot_lock import FootLock, OwnContact
from motion_style_ros.core.motion import Motion
from motion_style_ros.evaluation import metrics
from motion_style_ros.io.datasets import ClipInfo, load_clip

WALK = "dataset-2_walk_normal_001"


@pytest.fixture(scope="module")
def walk(datasets):
    path = datasets / f"bandai-namco/Bandai-Namco-Research-Motiondataset-2/data/{WALK}.bvh"
    return load_clip(ClipInfo("bandai-2", path, WALK, "walk", "normal", "", ""))


def locked(motion: Motion, lock: FootLock, source: Motion | None = None) -> Motion:
    """``motion`` frame by frame through ``lock``, with contacts from ``source`` (default: itself);
    a root the lock held back goes on from there, as a session's integrated trajectory does (its
    ground point: the pelvis height is the stylizer's every frame)."""
    roots = motion.positions[:, motion.skeleton.pelvis]
    ankles = (source or motion).global_positions()[:, lock.ankles]
    moved, out_q, out_p = np.zeros(3), [], []
    for t in range(motion.n_frames):
        q, p = lock(motion.rotations[t:t + 1], roots[t:t + 1] + moved, ankles[t:t + 1])
        moved = (p[0] - roots[t]) * [1.0, 0.0, 1.0]
        out_q.append(q)
        out_p.append(p)
    return Motion.from_rotations(motion.skeleton, np.concatenate(out_q), np.concatenate(out_p), motion.fps)


def sliding(motion: Motion, push: float = 0.3) -> Motion:
    """The walk with its root pushed ``push`` (30 %) further along its path: every planted foot slides."""
    roots = motion.positions[:, motion.skeleton.pelvis].copy()
    step = np.diff(roots[:, [0, 2]], axis=0, prepend=roots[:1, [0, 2]])
    roots[:, [0, 2]] += push * np.cumsum(step, axis=0)
    return Motion.from_rotations(motion.skeleton, motion.rotations, roots, motion.fps)


def test_locking_cuts_foot_skating_and_leaves_the_rest_alone(walk):
    slid = sliding(walk)
    fixed = locked(slid, FootLock(1, walk.fps), source=walk)
    before, after = metrics.foot_skating(slid), metrics.foot_skating(fixed)
    assert after < 0.8 * before, (before, after)
    assert np.isfinite(fixed.rotations).all()
    legs = [walk.skeleton.index(n) for n in ("UpperLeg_L", "LowerLeg_L", "Foot_L",
                                             "UpperLeg_R", "LowerLeg_R", "Foot_R")]
    others = [j for j in range(walk.skeleton.n_joints) if j not in legs]
    assert np.array_equal(fixed.rotations[:, others], slid.rotations[:, others])
    pelvis = walk.skeleton.pelvis
    assert np.array_equal(fixed.positions[:, pelvis, 1], slid.positions[:, pelvis, 1])
    assert metrics.bone_length_error(fixed, walk.skeleton) < 1e-9
    # No pops: a locked leg turns about as fast as the input's legs do at most.
    def largest_step(m):
        return np.degrees(rot.angle_between(m.rotations[1:, legs], m.rotations[:-1, legs])).max()
    assert largest_step(fixed) < 1.6 * largest_step(walk)


def test_own_contact_plants_a_low_ankle_where_it_came_down():
    own = OwnContact(1, 30.0, speed=np.inf)
    low, high = np.array([[[0.0, 0.05, 0.0], [0.3, 0.5, 0.0]]]), np.array([[[0.0, 0.5, 0.0], [0.3, 0.5, 0.0]]])
    assert np.array_equal(own(low), low)
    slid = low + [[[0.2, 0.0, 0.1], [0.0, 0.0, 0.0]]]
    assert np.array_equal(own(slid)[0, 0], low[0, 0])  # still down: held where it came down
    assert np.array_equal(own(high), high)  # lifted: as it is
    assert np.array_equal(own(slid)[0, 0], slid[0, 0])  # down again: planted anew
    own.reset()
    assert np.array_equal(own(low), low)  # after a reset nothing is held over the jump
    # with a speed limit, a foot skimming the floor fast is not planted
    fast = OwnContact(1, 30.0)
    fast(low)
    assert np.array_equal(fast(slid), slid)


def test_a_stream_with_no_input_holds_its_own_planted_feet(walk):
    """A generated stream (the learned performer's) has no input: its own low, slow feet are held."""
    slid, sk = sliding(walk, 0.1), walk.skeleton
    lock = FootLock(1, walk.fps, max_stretch=0.3)
    roots = slid.positions[:, sk.pelvis]
    moved, out_q, out_p = np.zeros(3), [], []
    for t in range(slid.n_frames):
        q, p = lock(slid.rotations[t:t + 1], roots[t:t + 1] + moved)  # no input ankles
        moved = (p[0] - roots[t]) * [1.0, 0.0, 1.0]
        out_q.append(q)
        out_p.append(p)
    fixed = Motion.from_rotations(sk, np.concatenate(out_q), np.concatenate(out_p), walk.fps)
    before, after = metrics.foot_skating(slid), metrics.foot_skating(fixed)
    assert after < 0.6 * before, (before, after)
    assert metrics.largest_jump(fixed) < 1.2 * metrics.largest_jump(walk)  # no pops
    # the held-back root covers less ground than the sliding one, about what the walk's legs cover
    travel = np.linalg.norm(fixed.positions[-1, sk.pelvis, [0, 2]] - fixed.positions[0, sk.pelvis, [0, 2]])
    assert travel < np.linalg.norm(roots[-1, [0, 2]] - roots[0, [0, 2]])


def test_a_clean_walk_is_barely_changed(walk):
    fixed = locked(walk, FootLock(1, walk.fps))
    change = np.degrees(rot.angle_between(fixed.rotations, walk.rotations))
    assert np.median(change) < 0.5 and np.percentile(change, 99) < 12.0
    assert metrics.foot_skating(fixed) <= metrics.foot_skating(walk) * 1.05


def test_reset_forgets_the_lock(walk):
    lock = FootLock(1, walk.fps)
    roots, ankles = walk.positions[:, 1], walk.global_positions()[:, lock.ankles]
    for t in range(10):
        lock(walk.rotations[t:t + 1], roots[t:t + 1], ankles[t:t + 1])
    lock.reset()
    # After a reset, a frame teleported a metre away is taken as it is (no leg pulled back).
    far = roots[10:11] + np.array([1.0, 0.0, 0.0])
    q, p = lock(walk.rotations[10:11], far, ankles[10:11] + [1.0, 0.0, 0.0])
    assert np.allclose(q, walk.rotations[10:11]) and np.array_equal(p, far)


def test_clearance_lifts_feet_the_input_lifts(walk):
    # The walk with its root 5 cm lower: the feet skim the floor and sink into it. With the
    # input's ankles as the guide, no ankle goes below the input's while the foot is in the air.
    roots = walk.positions[:, walk.skeleton.pelvis] - np.array([0.0, 0.05, 0.0])
    low = Motion.from_rotations(walk.skeleton, walk.rotations, roots, walk.fps)
    lock = FootLock(1, walk.fps)
    fixed = locked(low, lock, source=walk)
    height = {name: m.global_positions()[:, lock.ankles, 1] for name, m in
              (("input", walk), ("low", low), ("fixed", fixed))}
    swing = height["input"] > 0.25  # well in the air
    assert (height["low"][swing] < height["input"][swing] - 0.04).all()
    assert np.allclose(height["fixed"][swing], height["input"][swing], atol=2e-3)
    assert metrics.bone_length_error(fixed, walk.skeleton) < 1e-9
    # Without it, feet in the air stay low (but for the fading release of a lock).
    plain = locked(low, FootLock(1, walk.fps, clearance=False), source=walk)
    assert np.mean(height["input"][swing] - plain.global_positions()[:, lock.ankles, 1][swing]) > 0.03


def test_a_held_foot_follows_on_a_leash_when_the_stylizer_walks_off(walk):
    # The input stands on both feet throughout; the "stylized" output walks away. The lock holds
    # all along, and the held ankle trails the stylizer's by max_stretch at most.
    lock = FootLock(1, walk.fps, anchor_root=False)
    sk = walk.skeleton
    roots = walk.positions[:, sk.pelvis]
    standing = Motion.from_rotations(sk, walk.rotations[:1].repeat(walk.n_frames, 0),
                                     roots[:1].repeat(walk.n_frames, 0), walk.fps)  # frame 0 held
    fixed = locked(walk, lock, source=standing)
    assert lock._locked.all()
    gap = np.linalg.norm(fixed.global_positions()[:, lock.ankles] - walk.global_positions()[:, lock.ankles], axis=-1)
    assert gap.max() < lock.max_stretch + 0.02
    travelled = np.linalg.norm(roots[-1, [0, 2]] - roots[0, [0, 2]])
    assert travelled > 1.0  # so the feet did follow, on the leash
    assert metrics.bone_length_error(fixed, sk) < 1e-9


def test_a_planted_foot_keeps_its_heading(walk):
    # The output's feet pivot about the ankle (2 degrees a frame about the foot's own axis); while a
    # foot is locked its toes point where they landed.
    sk = walk.skeleton
    ankles = [sk.index(n) for n in ("Foot_L", "Foot_R")]
    spin = rot.from_yaw(np.radians(2.0) * np.arange(walk.n_frames))[:, None]
    rotations = walk.rotations.copy()
    rotations[:, ankles] = rot.multiply(rotations[:, ankles], spin)
    pivoting = Motion.from_rotations(sk, rotations, walk.positions[:, sk.pelvis], walk.fps)
    lock = FootLock(1, walk.fps)
    roots, inputs = pivoting.positions[:, sk.pelvis], walk.global_positions()[:, lock.ankles]
    toes = [sk.index(n) for n in ("Toes_L", "Toes_R")]
    headings, held = [], []
    for t in range(walk.n_frames):
        out, root = lock(pivoting.rotations[t:t + 1], roots[t:t + 1], inputs[t:t + 1])
        g = Motion.from_rotations(sk, out, root, walk.fps).global_positions()[0]
        forward = g[toes] - g[ankles]
        headings.append(np.arctan2(forward[:, 0], forward[:, 2]))
        held.append(lock._locked[0].copy())
    headings, held = np.array(headings), np.array(held)
    both = held[1:] & held[:-1]
    assert both.sum() > 0.2 * walk.n_frames
    turn = np.abs(np.angle(np.exp(1j * np.diff(headings, axis=0))))
    assert turn[both].max() < 1e-6
    assert np.median(turn[~both]) > np.radians(1.0)  # the stylizer's pivot elsewhere


def test_an_anchored_root_covers_the_ground_its_legs_cover(walk):
    # The walk's root pushed 30 % further than its legs carry it: with the leash alone the planted
    # feet are dragged after it; anchored, the root is held back instead, never past standing still.
    slid = sliding(walk)
    anchored = locked(slid, FootLock(1, walk.fps), source=walk)
    leashed = locked(slid, FootLock(1, walk.fps, anchor_root=False), source=walk)
    assert metrics.foot_skating(anchored) < 0.85 * metrics.foot_skating(leashed)  # 0.80 measured
    pelvis = walk.skeleton.pelvis
    step = {name: np.diff(m.positions[:, pelvis][:, [0, 2]], axis=0)
            for name, m in (("walk", walk), ("slid", slid), ("anchored", anchored))}
    assert (np.linalg.norm(step["anchored"], axis=-1) <= np.linalg.norm(step["slid"], axis=-1) + 1e-9).all()
    assert (np.einsum("ij,ij->i", step["anchored"], step["slid"]) >= -1e-12).all()  # never backwards
    travelled = {name: np.linalg.norm(s.sum(axis=0)) for name, s in step.items()}
    assert travelled["anchored"] < 0.5 * (travelled["walk"] + travelled["slid"])  # nearer the walk's
    assert metrics.bone_length_error(anchored, walk.skeleton) < 1e-9



def test_a_forward_foot_is_lifted_at_the_hip_a_rear_one_at_the_knee(walk):
    """The walk 5 cm lower than its input (another rig's floor): clearance lifts the swinging feet
    to the input's; a foot in front of its hip by swinging the leg up (its knee as the walk's
    own), one behind it at the knee."""
    from motion_style_ros.evaluation.posture import leg_angles

    roots = walk.positions[:, walk.skeleton.pelvis] - np.array([0.0, 0.05, 0.0])
    low = Motion.from_rotations(walk.skeleton, walk.rotations, roots, walk.fps)
    lock = FootLock(1, walk.fps)
    fixed = locked(low, lock, source=walk)
    sk, g = walk.skeleton, walk.global_positions()
    ankles, hips = g[:, lock.ankles], g[:, [sk.index("UpperLeg_L"), sk.index("UpperLeg_R")]]
    facing = np.diff(roots[:, [0, 2]], axis=0, append=roots[-1:, [0, 2]] - roots[-2:-1, [0, 2]])
    facing /= np.linalg.norm(facing, axis=-1, keepdims=True)
    ahead = np.einsum("tsc,tc->ts", (ankles - hips)[..., [0, 2]], facing)
    speed = np.linalg.norm(np.diff(ankles, axis=0, prepend=ankles[:1]), axis=-1) * walk.fps
    lifted = (ankles[..., 1] > 0.13) & (speed > 0.3)  # off the floor and moving: clearance holds it up
    n = walk.n_frames
    knee_in, knee_out = (leg_angles(m)["knee"].reshape(2, n).T for m in (walk, fixed))
    forward, behind = lifted & (ahead > 0.15), lifted & (ahead < -0.15)
    assert forward.sum() > 10 and behind.sum() > 10
    assert np.abs(knee_out[forward] - knee_in[forward]).mean() < 2.0
    assert (knee_out[behind] - knee_in[behind]).mean() > 5.0


def test_strength_turns_the_correction_only_that_far(walk):
    slid = sliding(walk)
    roots, ankles = slid.positions[:, slid.skeleton.pelvis], walk.global_positions()[:, FootLock(1, 30.0).ankles]
    full, none, half = (FootLock(1, walk.fps) for _ in range(3))
    for t in range(60):
        args = slid.rotations[t:t + 1], roots[t:t + 1], ankles[t:t + 1]
        q1, p1 = full(*args)
        q0, p0 = none(*args, strength=np.zeros(1))
        qh, ph = half(*args, strength=np.full(1, 0.5))
        assert np.array_equal(q0, slid.rotations[t:t + 1]) and np.array_equal(p0, roots[t:t + 1])
        assert np.allclose(ph, 0.5 * (p0 + p1))
        assert np.allclose(rot.angle_between(qh, q0), rot.angle_between(qh, q1), atol=1e-9)
