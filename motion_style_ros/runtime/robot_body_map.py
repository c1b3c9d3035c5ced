"""Which links of a humanoid robot play the human's bones: the body map of
:class:`~motion_style_ros.runtime.robot_target.RobotTarget`, from the URDF's names and tree (see
:mod:`motion_style_ros.runtime.robot_kinematics`) or a YAML map.

Which links are which
---------------------
From the URDF's names and tree: the knee and elbow joints are the actuated joints whose names
contain ``knee`` / ``elbow`` and ``left``/``l`` or ``right``/``r`` (else the side their origin lies
on at the zero pose, +Y being left). The hip joints are those above a knee that the other knee does
not share, the ankle joints those below it on the way to the lowest link of the leg (the foot); the
shoulder joints are those above an elbow that the other elbow does not share, the waist/torso joints
those both elbows share, the wrist joints those below an elbow. A group of joints acts at the point
nearest all its axes (a hip's centre); a knee or elbow at its joint origin. A forearm without a
wrist ends at the farthest centre of mass below the elbow. The soles are the lowest points of the
foot link's primitive collision shapes. Where names do not say it, a YAML map names the four
anchors (``left_knee``, ``right_knee``, ``left_elbow``, ``right_elbow``: joint names; optionally
``left_foot``, ``right_foot``: link names); anything missing is a one-line
:class:`~motion_style_ros.errors.MotionStyleError`.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from motion_style_ros.core.skeleton import Skeleton
from motion_style_ros.errors import MotionStyleError
from motion_style_ros.io import files
from motion_style_ros.io.urdf import RobotModel
from motion_style_ros.runtime.robot_kinematics import Kinematics

MAP_KEYS = ("left_knee", "right_knee", "left_elbow", "right_elbow", "left_foot", "right_foot")


@dataclass
class BodyMap:
    """The robot points that stand for the human's joints, and the segments between them."""

    segments: list[str]  # torso, shoulders, thigh_L, shin_L, upper_arm_L, forearm_L[, hand_L], ..._R
    S: np.ndarray  # (S, P): segment vectors as rows of S @ points
    seg_weights: np.ndarray  # (S,) residual weight of each segment's direction
    human_segments: list[tuple]  # (S,) the human bone (start, end) joint names of each segment
    pt_body: np.ndarray  # (P,) the body each point rides on
    pt_local: np.ndarray  # (P, 3) each point in its body's frame
    feet: list[dict]  # left, right: body, sole and contact points, sole axes, ankle/hip/knee joints
    leg_length: float  # hip centre to knee to ankle centre, mean of both legs (m)
    standing_height: float  # root height above the soles at the zero pose (m)
    report: dict  # the joint and link names found (RobotTarget.body_map)


def side_of_name(name: str) -> str | None:
    low = name.lower()
    tokens = set(low.replace("-", "_").replace(".", "_").split("_"))
    if "left" in low or "l" in tokens:
        return "left"
    if "right" in low or "r" in tokens:
        return "right"
    return None


def load_map(path: str | Path) -> dict[str, str]:
    """A body map YAML: ``left_knee: JOINT`` ... (keys :data:`MAP_KEYS`); one-line errors."""
    from ruamel.yaml import YAML, YAMLError

    path = Path(path)
    try:
        data = YAML(typ="safe").load(files.read_bytes(path, "body map").decode("utf-8"))
    except UnicodeDecodeError as exc:
        raise MotionStyleError(f"{path}: cannot read the body map ({exc})") from None
    except YAMLError as exc:
        raise MotionStyleError(f"{path}: not valid YAML ({' '.join(str(exc).split())})") from None
    except RecursionError:
        raise MotionStyleError(f"{path}: not a body map (YAML nested too deeply)") from None
    except ValueError as exc:  # an int of over 4300 digits
        raise MotionStyleError(f"{path}: not a body map ({' '.join(str(exc).split())})") from None
    if not isinstance(data, dict) or not all(isinstance(v, str) for v in data.values()):
        raise MotionStyleError(f"{path}: a body map is a mapping of {', '.join(MAP_KEYS)} to names")
    unknown = set(data) - set(MAP_KEYS)
    if unknown:
        raise MotionStyleError(f"{path}: unknown keys {sorted(map(str, unknown))}; allowed: "
                               f"{', '.join(MAP_KEYS)}")
    return dict(data)



def build(kin: Kinematics, model: RobotModel, overrides: dict[str, str], weights) -> BodyMap:
    """The body map of ``kin`` (``model``'s actuated tree), anchors named in ``overrides`` (keys
    :data:`MAP_KEYS`) where names do not say them; ``weights`` (a ``robot_target.Weights``) weigh
    the segments."""
    src = model.source
    t0 = kin.fk(np.zeros(kin.n))
    o0 = t0[1:, :3, 3]
    w0 = np.einsum("kij,kj->ki", t0[1:, :3, :3], kin.axes)
    names = kin.names
    points: list[tuple[int, np.ndarray]] = []  # (body, point in the body frame)

    def attach(body: int, world: np.ndarray) -> int:
        t = t0[body]
        points.append((body, t[:3, :3].T @ (world - t[:3, 3])))
        return len(points) - 1

    def centre(group: list[int]) -> np.ndarray:
        """The point nearest all the group's axis lines (nearest the first origin if parallel)."""
        a = 1e-3 * np.eye(3)
        b = 1e-3 * o0[group[0]]
        for k in group:
            proj = np.eye(3) - np.outer(w0[k], w0[k])
            a, b = a + proj, b + proj @ o0[k]
        return np.linalg.solve(a, b)

    def side_of(k: int) -> str | None:
        return side_of_name(names[k]) or ("left" if o0[k, 1] > 0.01
                                          else "right" if o0[k, 1] < -0.01 else None)

    def anchor(role: str, side: str) -> int:
        key = f"{side}_{role}"
        if key in overrides:
            if overrides[key] not in names:
                raise MotionStyleError(f"{src}: the body map's {key} {overrides[key]!r} is no "
                                       f"actuated joint of the robot")
            return names.index(overrides[key])
        found = [k for k in range(kin.n) if role in names[k].lower() and side_of(k) == side]
        if not found:
            raise MotionStyleError(
                f"{src}: no {side} {role} joint (an actuated joint named like '*{side}*{role}*'); "
                f"is it a humanoid? Name it in a body map ({key}: JOINT_NAME)")
        return min(found, key=lambda k: len(kin.path(k + 1)))

    def subtree(k: int) -> list[int]:
        return [b for b in range(1, kin.n + 1) if k in kin.path(b)]

    def links_of(bodies: list[int]) -> list[str]:
        return [link for link, b in kin.link_body.items() if b in bodies]

    def world_of(link: str, local: np.ndarray) -> np.ndarray:
        t = t0[kin.link_body[link]] @ kin.link_T[link]
        return t[:3, :3] @ local + t[:3, 3]

    knee = {s: anchor("knee", s) for s in ("left", "right")}
    elbow = {s: anchor("elbow", s) for s in ("left", "right")}
    seg_names, seg_a, seg_b, seg_w, human = [], [], [], [], []
    w = weights
    feet = {}
    leg_lengths = []

    def segment(name, a, b, weight, h):
        seg_names.append(name)
        seg_a.append(a)
        seg_b.append(b)
        seg_w.append(weight)
        human.append(h)

    hip_pts, shoulder_pts = {}, {}
    for s, other in (("left", "right"), ("right", "left")):
        tag = s[0].upper()
        kp = kin.path(knee[s] + 1)
        shared = set(kin.path(knee[other] + 1))
        hips = [k for k in kp[:-1] if k not in shared]
        if not hips:
            raise MotionStyleError(f"{src}: no hip joints above the {s} knee {names[knee[s]]!r}")
        below = subtree(knee[s])
        foot_key = f"{s}_foot"
        if foot_key in overrides:
            if overrides[foot_key] not in kin.link_body:
                raise MotionStyleError(f"{src}: the body map's {foot_key} {overrides[foot_key]!r} "
                                       f"is no link of the robot")
            foot = kin.link_body[overrides[foot_key]]
        else:
            foot = min(below, key=lambda b: (round(t0[b][2, 3], 3), -len(kin.path(b))))
        ankles = [k for k in kin.path(foot) if k not in kp and "toe" not in names[k].lower()]
        hip_c, knee_c = centre(hips), o0[knee[s]]
        contacts = [world_of(link, p) for link in links_of([foot]) if link in model.shapes
                    for p in model.shapes[link]]
        if contacts:
            contacts = np.array(contacts)
            contacts = contacts[contacts[:, 2] < contacts[:, 2].min() + 0.005]
        else:  # no primitive shapes: the foot body's origin stands in for its sole
            contacts = t0[foot][None, :3, 3]
        sole = contacts.mean(axis=0)
        ankle_c = centre(ankles) if ankles else sole
        hip_pts[s] = attach(int(kin.body_parent[hips[0]]), hip_c)
        knee_p = attach(int(kin.body_parent[knee[s]]), knee_c)
        ankle_p = attach(int(kin.body_parent[ankles[0]]) if ankles else foot, ankle_c)
        leg_lengths.append(np.linalg.norm(knee_c - hip_c) + np.linalg.norm(ankle_c - knee_c))
        segment(f"thigh_{tag}", hip_pts[s], knee_p, w.limb, (f"UpperLeg_{tag}", f"LowerLeg_{tag}"))
        segment(f"shin_{tag}", knee_p, ankle_p, w.limb, (f"LowerLeg_{tag}", f"Foot_{tag}"))
        rf = t0[foot][:3, :3]
        feet[s] = dict(body=foot, sole=attach(foot, sole),
                       contacts=[attach(foot, c) for c in contacts],
                       x=rf.T @ np.array([1.0, 0, 0]), z=rf.T @ np.array([0, 0, 1.0]),
                       joints=ankles, hips=hips, knee=knee[s])

        ep = kin.path(elbow[s] + 1)
        shared = set(kin.path(elbow[other] + 1))
        shoulders = [k for k in ep[:-1] if k not in shared]
        if not shoulders:
            raise MotionStyleError(f"{src}: no shoulder joints above the {s} elbow {names[elbow[s]]!r}")
        torso_joints = [k for k in ep[:-1] if k in shared]
        sh_c, el_c = centre(shoulders), o0[elbow[s]]
        shoulder_pts[s] = attach(int(kin.body_parent[shoulders[0]]), sh_c)
        elbow_p = attach(int(kin.body_parent[elbow[s]]), el_c)
        below = subtree(elbow[s])
        hand = max(below, key=lambda b: (len(kin.path(b)), np.linalg.norm(t0[b][:3, 3] - el_c)))
        wrists = [k for k in kin.path(hand) if k not in ep]

        def farthest(bodies, start):
            cands = [(link, np.zeros(3)) for link in links_of(bodies)]
            cands += [(link, model.coms[link]) for link in links_of(bodies) if link in model.coms]
            link, local = max(cands, key=lambda c: np.linalg.norm(world_of(*c) - start))
            return kin.link_body[link], world_of(link, local)

        segment(f"upper_arm_{tag}", shoulder_pts[s], elbow_p, w.limb,
                (f"UpperArm_{tag}", f"LowerArm_{tag}"))
        if wrists:
            wr_c = centre(wrists)
            wrist_p = attach(int(kin.body_parent[wrists[0]]), wr_c)
            segment(f"forearm_{tag}", elbow_p, wrist_p, w.limb, (f"LowerArm_{tag}", f"Hand_{tag}"))
            hb, end = farthest([hand], wr_c)
            if np.linalg.norm(end - wr_c) > 0.02:
                segment(f"hand_{tag}", wrist_p, attach(hb, end), w.hand, (f"Hand_{tag}", None))
        else:
            hb, end = farthest(below, el_c)
            segment(f"forearm_{tag}", elbow_p, attach(hb, end), w.limb, (f"LowerArm_{tag}", f"Hand_{tag}"))

    torso = torso_joints
    base_c = centre(torso) if torso else np.zeros(3)
    base_p = attach(int(kin.body_parent[torso[0]]) if torso else 0, base_c)
    n_pts = len(points)
    # Segment vectors as rows of S @ P; the torso ends midway between the shoulders.
    mid = np.zeros(n_pts)
    mid[[shoulder_pts["left"], shoulder_pts["right"]]] = 0.5
    rows = []
    for a, b in zip(seg_a, seg_b):
        r = np.zeros(n_pts)
        r[b] += 1.0
        r[a] -= 1.0
        rows.append(r)
    base_row = mid.copy()
    base_row[base_p] -= 1.0
    line = np.zeros(n_pts)
    line[shoulder_pts["left"]], line[shoulder_pts["right"]] = 1.0, -1.0
    rows = [base_row, line] + rows
    seg_names = ["torso", "shoulders"] + seg_names
    seg_w = [w.torso, w.shoulders] + seg_w
    human = [("Hips", "shoulders"), ("UpperArm_R", "UpperArm_L")] + human
    pt_body = np.array([b for b, _ in points])
    pt_local = np.array([p for _, p in points])
    feet_lr = [feet["left"], feet["right"]]
    contacts = [np.array(f["contacts"]) for f in feet_lr]
    lowest = min(float(t0[pt_body[c]][2, 3] + (t0[pt_body[c]][:3, :3] @ pt_local[c])[2])
                 for f in contacts for c in f)
    report = {
        "knee": {s: names[knee[s]] for s in knee}, "elbow": {s: names[elbow[s]] for s in elbow},
        "hip": {s: [names[k] for k in feet[s]["hips"]] for s in feet},
        "ankle": {s: [names[k] for k in feet[s]["joints"]] for s in feet},
        "foot": {s: [link for link, b in kin.link_body.items() if b == feet[s]["body"]][0] for s in feet},
        "torso": [names[k] for k in torso], "segments": list(seg_names),
    }
    return BodyMap(segments=seg_names, S=np.array(rows), seg_weights=np.array(seg_w), human_segments=human,
                   pt_body=pt_body, pt_local=pt_local, feet=feet_lr, leg_length=float(np.mean(leg_lengths)),
                   standing_height=-lowest, report=report)


def human_ends(sk: Skeleton, human_segments: list[tuple], hands: list[int]):
    """The human side of each segment as rows over ``sk``'s joint positions: ``(A, B)`` averaging
    its start and end joints (``"shoulders"``: both upper arms), and ``(row, side)`` of each segment
    with no end joint (a hand, whose direction comes from the hand's rotation)."""
    idx = sk.index
    ends = []
    for a, b in human_segments:
        ra = [idx("UpperArm_L"), idx("UpperArm_R")] if a == "shoulders" else [idx(a)]
        rb = ([idx("UpperArm_L"), idx("UpperArm_R")] if b == "shoulders" else [] if b is None
              else [idx(b)])
        ends.append((ra, rb))
    n = len(ends)
    h_a = np.zeros((n, sk.n_joints))
    h_b = np.zeros((n, sk.n_joints))
    hand_rows = []
    for i, (ra, rb) in enumerate(ends):
        h_a[i, ra] = 1.0 / len(ra)
        if rb:
            h_b[i, rb] = 1.0 / len(rb)
        else:
            hand_rows.append((i, 0 if ra[0] == hands[0] else 1))
    return h_a, h_b, hand_rows
