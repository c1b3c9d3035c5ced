"""``motion-style bench nodes``: a real stylizer process over DDS, measured from this side.

Only the shape and the counts of its table are checked (speed is the bench's to print, not a test's
to assert); a random-weight model stands in for the shipped one.
"""

import subprocess
import sys

from onnx_fixtures import recurrent_model

STYLES = ["active", "elderly", "exhausted", "feminine", "masculine", "normal", "youthful"]


def test_bench_nodes_measures_every_row(tmp_path, ros_env):
    model = recurrent_model(tmp_path / "style_erd.onnx", STYLES)
    result = subprocess.run(
        [sys.executable, "-m", "motion_style_ros.cli.main", "bench", "nodes", "--model", str(model),
         "--rates", "60", "--performers", "2,3", "--seconds", "1", "--workers", "2"],
        capture_output=True, text=True, timeout=400, env=ros_env,
    )
    assert result.returncode == 0, result.stdout + result.stderr
    lines = result.stdout.splitlines()
    assert "random-weight model" in result.stdout and "load average" in result.stdout
    assert "the nodes spin in rclpy's events executor (MOTION_STYLE_EXECUTOR)" in result.stdout
    header = next(i for i, line in enumerate(lines) if line.split()[:4] == ["node", "processes", "rate", "(Hz)"])
    rows = [line.split() for line in lines[header + 1:header + 9]]
    # each several-performer stylizer row again with the performers shared over two processes
    assert [r[:4] for r in rows] == [["relay", "1", "60", "1"], ["stylizer", "1", "60", "1"],
                                     ["relay", "1", "60", "2"], ["stylizer", "1", "60", "2"],
                                     ["stylizer", "2", "60", "2"], ["relay", "1", "60", "3"],
                                     ["stylizer", "1", "60", "3"], ["stylizer", "2", "60", "3"]]
    for node, processes, rate, performers, frames, p50, p99, worst, dropped, node_p99, cpu, own, delay in rows:
        assert int(frames) >= 10 * int(performers)  # about 60 per performer
        assert 0 < float(p50) <= float(p99) <= float(worst)
        # the stylizer reports its own latency (NaN fails); the relay has no diagnostics
        assert float(node_p99) > 0 if node == "stylizer" else node_p99 == "nan"
        assert 0 <= int(dropped) < int(frames) and float(cpu) > 0 and float(own) > 0
        # the session's latency at 60 Hz input: one 30 Hz model frame less one input frame
        assert float(delay) == (16.7 if node == "stylizer" else 0.0)
    # the largest count held is the largest one-process stylizer row with nothing dropped and p99 within 10 ms
    held = [int(r[3]) for r in rows if r[:2] == ["stylizer", "1"] and r[8] == "0" and float(r[6]) <= 10]
    summary = next(line for line in lines if line.startswith("the stylizer held"))
    assert summary.endswith(f"{max(held)} performers of 1, 2, 3 tried" if held else "none of the counts of 1, 2, 3 tried")


def test_bench_soak_samples_every_minute_and_reads_the_bag_back(tmp_path, ros_env):
    """A 6-second soak: one sample row (memory, CPU, counts, latency) and the bag read back."""
    import json
    import re

    result = subprocess.run(
        [sys.executable, "-m", "motion_style_ros.cli.main", "bench", "soak", "--minutes", "0.1",
         "--rate", "60", "--out", str(tmp_path)],
        capture_output=True, text=True, timeout=400, env=ros_env,
    )
    assert result.returncode == 0, result.stdout + result.stderr
    row = re.search(r"minute 1 rss_mb ([\d.]+) cpu_percent ([\d.]+) frames_in (\d+) frames_out (\d+) "
                    r"dropped (\d+) latency_p50_ms ([\d.]+)", result.stdout)
    assert row, result.stdout
    rss, cpu, frames_in, frames_out, dropped, p50 = map(float, row.groups())
    assert rss > 50 and cpu > 0 and frames_in >= 200 and frames_out <= frames_in and p50 > 0
    summary = json.loads((tmp_path / "soak.json").read_text())
    assert summary["bag_frames"]["/joint_states"] > 200 and summary["bag_frames"]["/stylized/joint_states"] > 200


def test_bench_faults_times_both_restarts_and_reads_the_bag_back(tmp_path, ros_env):
    """One cycle: the performer and then the stylizer killed and started again; both come back and
    the bag holds the input's frames and only stylized frames of real input frames."""
    import json

    result = subprocess.run(
        [sys.executable, "-m", "motion_style_ros.cli.main", "bench", "faults", "--cycles", "1",
         "--rate", "60", "--pause", "0.5", "--out", str(tmp_path)],
        capture_output=True, text=True, timeout=400, env=ros_env,
    )
    assert result.returncode == 0, result.stdout + result.stderr
    summary = json.loads((tmp_path / "faults.json").read_text())
    (cycle,) = summary["cycles"]
    assert cycle["performer_first_frame_ms"] > 0 and cycle["then_first_stylized_ms"] >= 0
    assert cycle["stylizer_first_stylized_ms"] > 0
    bag = summary["bag"]
    assert bag["input_frames"] > 60 and bag["stylized_frames"] > 60
    assert bag["of_them_while_the_stylizer_was_down"] == 0  # the stylizer's fault costs the recording nothing
    assert bag["stylized_stamps_not_an_input_stamp"] == 0
