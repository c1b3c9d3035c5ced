"""``motion-style eval --live`` on one clip: a CMU walk through real nodes (``bvh_player`` ->
``stylizer``, separate processes over DDS, the walk retargeted but not conformed, as a live rig
sends it) matches ``motion-style stylize`` of the same clip after its first second."""

import json
import subprocess
import sys


def test_a_live_cmu_walk_matches_the_offline_one(tmp_path, ros_env, datasets):
    out = tmp_path / "live"
    result = subprocess.run(
        [sys.executable, "-m", "motion_style_ros.cli.main", "eval", "--stylizer", "recurrent", "--live",
         "--live-clips", "07_03", "--live-styles", "elderly", "--no-proportions", "--quiet",
         "--out", str(out)],
        capture_output=True, text=True, timeout=400, env=dict(ros_env, MOTION_STYLE_DATASETS=str(datasets)),
    )
    assert result.returncode == 0, result.stdout + result.stderr
    (row,) = json.loads((out / "live_recurrent.json").read_text())["clips"]
    assert row["clip"] == "07_03.bvh" and row["frames_in"] == 415  # from frame 1: frame 0 is a T-pose
    assert row["frames_out"] == row["frames_in"]  # reliable from end to end
    # Before conditioning moved into the session, this walk came out with a hand above its
    # shoulder in about 60 % of its frames live and none offline.
    assert row["joint_distance_cm"] <= 3.0 and row["rotation_deg"] <= 5.0, row
    assert abs(row["hands_up_live"] - row["hands_up_offline"]) <= 0.02, row
