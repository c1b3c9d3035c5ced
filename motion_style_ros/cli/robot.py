"""``motion-style robot``: stylized motion on a real humanoid robot (a URDF).

``check`` stylizes every CMU and Xia neutral clip, maps each output onto each robot and prints the
limit counts, how closely the robot's links follow the human's bones and how well the planted feet
stay on the floor; ``map`` maps one clip and writes the joint positions.
"""

from __future__ import annotations

import argparse

from motion_style_ros.runtime.backends import BACKENDS

DEFAULT_STYLES = ("elderly", "youthful")


def add_parser(subparsers) -> None:
    p = subparsers.add_parser(
        "robot", help="map (stylized) motion onto a humanoid robot's joints (URDF)",
        description="Map canonical-skeleton motion onto a humanoid robot described by a URDF: "
                    "its links follow the human's bones (torso, thighs, shins, upper arms, "
                    "forearms, hands), planted feet stay on the floor, every joint within its "
                    "position and velocity limits.",
    )
    sub = p.add_subparsers(dest="robot_command", metavar="ACTION", required=True)
    c = sub.add_parser(
        "check", help="stylize every CMU and Xia neutral clip and map the outputs onto robots",
        description="Stylize every CMU and Xia neutral clip into each --style, map each output "
                    "onto each robot (streaming, as a node would) and print per robot: clips, "
                    "frames, limit violations before clamping, values clamped, link-vs-bone "
                    "angles, planted-foot height errors and milliseconds per frame; write a JSON "
                    "report and a picture of robot and human side by side.")
    c.add_argument("--urdf", action="append", required=True, metavar="PATH",
                   help="robot description (repeat for several robots)")
    c.add_argument("--map", action="append", default=None, metavar="YAML",
                   help="body map of the --urdf at the same position (knee/elbow joint names), "
                        "where the URDF's names do not say them")
    c.add_argument("--style", action="append", default=None,
                   help=f"target style (repeat for several; default: {', '.join(DEFAULT_STYLES)})")
    c.add_argument("--unstyled", action="store_true",
                   help="map the neutral clips themselves instead of stylized outputs")
    c.add_argument("--backend", default="recurrent", choices=tuple(BACKENDS),
                   help="stylizer backend (default: recurrent)")
    c.add_argument("--model", default=None, help="model file (default: the backend's shipped model)")
    c.add_argument("--clips", type=int, default=None, metavar="N",
                   help="only the first N clips (default: all)")
    c.add_argument("--out", default="robot_check", metavar="DIR",
                   help="where the JSON report and the picture go (default: robot_check)")
    c.set_defaults(func=run_check)
    m = sub.add_parser(
        "map", help="map one BVH clip onto a robot and write its joint positions",
        description="Map a humanoid BVH clip (optionally stylized first) onto a robot; write the "
                    "joint positions per frame (CSV: time, base x y z qw qx qy qz, then the "
                    "joints in URDF order; NPZ: arrays names, time, positions, base_position, "
                    "base_orientation).")
    m.add_argument("input", metavar="CLIP.bvh", help="source clip")
    m.add_argument("--urdf", required=True, metavar="PATH", help="robot description")
    m.add_argument("--map", default=None, metavar="YAML", help="body map (knee/elbow joint names)")
    m.add_argument("--out", required=True, metavar="OUT.csv|OUT.npz", help="where to write")
    m.add_argument("--style", default=None, help="stylize into this style first")
    m.add_argument("--backend", default="recurrent", choices=tuple(BACKENDS),
                   help="stylizer backend for --style (default: recurrent)")
    m.set_defaults(func=run_map)


def _figures(rows: list[dict], angles: list, errors: list, seconds: float) -> dict:
    import numpy as np

    a = np.concatenate([x.ravel() for x in angles]) if angles else np.zeros(0)
    e = np.concatenate(errors) if errors else np.zeros(0)
    frames = sum(r["frames"] for r in rows)
    keys = ("position_violations", "velocity_violations", "clamped", "at_position_limit",
            "position_violations_after", "velocity_violations_after")
    return {
        "clips": len(rows), "frames": frames,
        **{k: int(sum(r[k] for r in rows)) for k in keys},
        "non_finite_outputs": int(sum(not r["finite"] for r in rows)),
        "angle_mean_deg": float(a.mean()) if a.size else None,
        "angle_p95_deg": float(np.percentile(a, 95)) if a.size else None,
        "planted_frames": int(e.size),
        "planted_height_median_m": float(np.median(e)) if e.size else None,
        "planted_height_p95_m": float(np.percentile(e, 95)) if e.size else None,
        "planted_within_2cm": float((e <= 0.02).mean()) if e.size else None,
        "ms_per_frame": 1000.0 * seconds / max(frames, 1),
    }


def _print(name: str, f: dict, segments: dict) -> None:
    print(f"{name}: {f['clips']} clips, {f['frames']} frames")
    print(f"  position-limit violations before clamping: {f['position_violations']}; "
          f"velocity-limit violations before clamping: {f['velocity_violations']}; "
          f"values clamped: {f['clamped']} (held at a position limit by the solve: "
          f"{f['at_position_limit']}); after clamping: {f['position_violations_after']} position, "
          f"{f['velocity_violations_after']} velocity; non-finite outputs: {f['non_finite_outputs']}")
    print(f"  link vs bone angle: mean {f['angle_mean_deg']:.2f} deg, 95th percentile "
          f"{f['angle_p95_deg']:.2f} deg; per link: "
          + ", ".join(f"{k} {v:.1f}" for k, v in segments.items()))
    if f["planted_frames"]:
        print(f"  planted feet ({f['planted_frames']} foot-frames): height error median "
              f"{100 * f['planted_height_median_m']:.2f} cm, 95th percentile "
              f"{100 * f['planted_height_p95_m']:.2f} cm, {100 * f['planted_within_2cm']:.1f}% within 2 cm")
    print(f"  {f['ms_per_frame']:.2f} ms per frame")


def _targets(urdfs: list[str], maps: list[str] | None):
    from motion_style_ros.runtime.robot_target import RobotTarget
    from motion_style_ros.errors import MotionStyleError

    maps = maps or []
    if len(maps) > len(urdfs):
        raise MotionStyleError(f"{len(maps)} --map files for {len(urdfs)} --urdf files")
    return [RobotTarget(u, body_map=maps[i] if i < len(maps) else None) for i, u in enumerate(urdfs)]


def run_check(args: argparse.Namespace) -> int:
    import json
    from pathlib import Path

    import numpy as np

    from motion_style_ros.evaluation.robot_target import evaluate
    from motion_style_ros.errors import MotionStyleError
    from motion_style_ros.evaluation.unseen import neutral_clips

    targets = _targets(args.urdf, args.map)  # bad URDFs fail before the slow part
    styles = [None] if args.unstyled else (args.style or list(DEFAULT_STYLES))
    stylize = None
    if not args.unstyled:
        from motion_style_ros.runtime.offline import stylizer

        stylize = stylizer(args.backend, args.model)
    clips = neutral_clips()
    if args.clips is not None:
        clips = clips[: max(args.clips, 0)]
    if not clips:
        raise MotionStyleError("no clips to check (are the CMU and Xia datasets unpacked?)")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    per_robot = [{"rows": [], "angles": [], "errors": [], "seconds": 0.0} for _ in targets]
    picture = None
    for title, clip in clips:
        for style in styles:
            motion = clip if style is None else stylize(clip, style)
            for target, acc in zip(targets, per_robot):
                mapping = target.map_clip(motion)
                e = evaluate(mapping, motion, target)
                acc["angles"].append(e.pop("angles"))
                acc["errors"].append(e.pop("planted_errors"))
                e["angle_mean_deg"] = float(acc["angles"][-1].mean())
                e["planted_within_2cm"] = (float((acc["errors"][-1] <= 0.02).mean())
                                           if acc["errors"][-1].size else None)
                acc["seconds"] += mapping.seconds
                e.pop("ms_per_frame")
                acc["rows"].append({"clip": title, "style": style or "input", **e})
                if picture is None and "walk" in title:
                    picture = (title, style, motion)
            if picture is None:
                picture = (title, style, motion)
    report = {"command": "motion-style robot check", "styles": [s or "input" for s in styles],
              "backend": None if args.unstyled else args.backend, "robots": {}}
    for target, acc in zip(targets, per_robot):
        f = _figures(acc["rows"], acc["angles"], acc["errors"], acc["seconds"])
        seg = dict(zip(target.segments, np.concatenate(acc["angles"]).mean(axis=0).round(2).tolist()))
        name = f"{target.model.name} ({target.model.source})"
        _print(name, f, seg)
        report["robots"][target.model.source] = {
            "name": target.model.name, "joints": len(target.names), "summary": f,
            "angle_mean_deg_per_link": seg, "body_map": target.body_map, "clips": acc["rows"]}
    path = out / "robot_check.json"
    path.write_text(json.dumps(report, indent=2) + "\n", encoding="utf-8")
    print(f"wrote {path}")
    png = out / "robot_check.png"
    draw(png, picture[2], targets, f"{picture[0]}, {picture[1] or 'input'}")
    print(f"wrote {png}")
    return 0


def draw(path, motion, targets, title: str, snapshots: int = 4) -> None:
    """Stick figures of the human (package FK) and each robot (URDF FK), side and front views, at
    a few moments of ``motion``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    from motion_style_ros.io.joint_state import to_ros

    human = to_ros(motion.global_positions())
    parents = motion.skeleton.parents
    pelvis = motion.skeleton.pelvis
    mappings = [t.map_clip(motion) for t in targets]
    frames = np.linspace(0, motion.n_frames - 1, snapshots + 2).round().astype(int)[1:-1]
    fig, axes = plt.subplots(2, snapshots, figsize=(3.2 * snapshots, 6.4), squeeze=False)
    colours = ["tab:orange", "tab:green", "tab:purple", "tab:red"]
    for col, i in enumerate(frames):
        for row, (h_axis, label) in enumerate(((0, "side (X forward)"), (1, "front (Y left)"))):
            ax = axes[row][col]
            centre = human[i, pelvis]
            for j, p in enumerate(parents):
                if p >= 0 and j != pelvis:
                    seg = human[i, [p, j]] - centre
                    ax.plot(seg[:, h_axis], seg[:, 2] + centre[2], color="tab:blue", lw=2)
            for k, (target, mapping) in enumerate(zip(targets, mappings)):
                base = (mapping.base_position[i], mapping.base_orientation[i])
                links, pos, link_parents = target.link_positions(mapping.positions[i], base)
                shift = np.zeros(3)
                shift[h_axis] = 0.8 * (k + 1)
                index = {name: n for n, name in enumerate(links)}
                bc = pos[0]
                for name, par in zip(links, link_parents):
                    if par is None:
                        continue
                    seg = pos[[index[par], index[name]]] - bc + shift
                    ax.plot(seg[:, h_axis], seg[:, 2] + bc[2], color=colours[k % len(colours)], lw=2)
            ax.axhline(0.0, color="0.6", lw=1)
            ax.set_aspect("equal")
            ax.set_xlim(-0.6, 0.8 * len(targets) + 0.6)
            ax.set_ylim(-0.05, 1.9)
            ax.set_title(f"{label}, t={i / motion.fps:.2f} s", fontsize=8)
            ax.tick_params(labelsize=7)
    names = ", ".join(f"{t.model.name} ({colours[k % len(colours)][4:]})" for k, t in enumerate(targets))
    fig.suptitle(f"{title}: human (blue) and {names}", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def run_map(args: argparse.Namespace) -> int:
    from pathlib import Path

    import numpy as np

    from motion_style_ros.errors import MotionStyleError
    from motion_style_ros.io.canonical import canonical_clip

    out = Path(args.out)
    if out.suffix.lower() not in (".csv", ".npz"):
        raise MotionStyleError(f"{out}: --out must end in .csv or .npz")
    (target,) = _targets([args.urdf], [args.map] if args.map else None)
    motion = canonical_clip(args.input)
    if args.style:
        from motion_style_ros.runtime.offline import stylizer

        motion = stylizer(args.backend)(motion, args.style)
    mapping = target.map_clip(motion)
    t = np.arange(motion.n_frames) / motion.fps
    if out.suffix.lower() == ".npz":
        np.savez(out, names=np.array(mapping.names), time=t, positions=mapping.positions,
                 base_position=mapping.base_position, base_orientation=mapping.base_orientation)
    else:
        header = ["time", "base_x", "base_y", "base_z", "base_qw", "base_qx", "base_qy", "base_qz"]
        table = np.column_stack([t, mapping.base_position, mapping.base_orientation, mapping.positions])
        np.savetxt(out, table, delimiter=",", header=",".join(header + mapping.names), comments="",
                   fmt="%.6f")
    s = mapping.stats
    print(f"wrote {out}: {motion.n_frames} frames, {len(mapping.names)} joints of {target.model.name}; "
          f"limit violations before clamping: {s['position_violations']} position, "
          f"{s['velocity_violations']} velocity; {s['clamped']} values clamped; link vs bone angle "
          f"mean {mapping.angles.mean():.2f} deg; "
          f"{1000 * mapping.seconds / max(motion.n_frames, 1):.2f} ms per frame")
    return 0
