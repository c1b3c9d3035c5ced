"""The evaluation harness on real held-out takes: pairing, baselines, report, `motion-style eval`."""

import json
import os
import subprocess
import sys
from collections import Counter

import numpy as np
import pytest
from onnx_fixtures import recurrent_model

from motion_style_ros.core import rotations as rot
from motion_style_ros.core.motion import Motion
from motion_style_ros.core.skeleton import cmu31
from motion_style_ros.errors import MotionStyleError
from motion_style_ros.evaluation import harness
from motion_style_ros.evaluation.judges import Judge


@pytest.fixture(scope="module")
def clips(datasets):
    return harness.held_out_clips(datasets, progress=False)


@pytest.fixture(scope="module")
def judges():
    return Judge("style"), Judge("content")


@pytest.fixture(scope="module")
def report(clips, judges):
    pairs = harness.make_pairs([info for info, _ in clips], pairs_per_cell=1, seed=0)
    return harness.evaluate(harness.baselines(clips), clips, pairs, *judges, progress=False)


def test_pairs_cover_every_cell_and_every_other_style(clips):
    infos = [info for info, _ in clips]
    styles = sorted({i.style for i in infos})
    pairs = harness.make_pairs(infos, pairs_per_cell=2, seed=0)
    sources = Counter(p.source.name for p in pairs)
    assert set(sources.values()) == {len(styles) - 1}
    assert all(p.target != p.source.style and p.target in styles for p in pairs)
    per_cell = Counter((p.source.content, p.source.style) for p in pairs)
    cells = {(i.content, i.style) for i in infos}
    assert set(per_cell) == cells and set(per_cell.values()) == {2 * (len(styles) - 1)}
    assert pairs == harness.make_pairs(infos, pairs_per_cell=2, seed=0)
    assert pairs != harness.make_pairs(infos, pairs_per_cell=2, seed=1)
    with pytest.raises(MotionStyleError):
        harness.make_pairs(infos, pairs_per_cell=0)


def test_oracle_returns_another_take_of_the_content_in_the_target_style(clips):
    oracle = harness.Oracle(clips, seed=0)
    info_of = {id(m): info for info, m in clips}
    for info, m in clips[::40]:
        target = "elderly" if info.style != "elderly" else "normal"
        out = info_of[id(oracle(m, target))]
        assert (out.content, out.style) == (info.content, target) and out.name != info.name
        assert oracle(m, target) is oracle(m, target)  # deterministic per pair


def test_oracle_skips_pairs_without_a_real_target_take(clips, judges):
    walks = [c for c in clips if c[0].content == "walk"]
    without = [c for c in walks if c[0].style != "feminine"]
    pairs = [harness.Pair(walks[0][0], "feminine"), harness.Pair(walks[0][0], "youthful")]
    pairs = [p for p in pairs if p.target != p.source.style]
    stylizers = {"oracle": harness.Oracle(without)}
    report = harness.evaluate(stylizers, walks, pairs, *judges, progress=False)
    skipped = report["systems"]["oracle"]["skipped"]
    assert [s["target"] for s in skipped] == ["feminine"] and "no test take" in skipped[0]["reason"]
    assert report["systems"]["oracle"]["overall"]["pairs"] == len(pairs) - 1


def test_pairs_into_a_style_the_model_was_not_trained_on_are_skipped_with_the_reason(clips, judges):
    walks = [c for c in clips if c[0].content == "walk"]
    pairs = [harness.Pair(walks[0][0], t) for t in ("feminine", "youthful") if t != walks[0][0].style]
    asked = []

    def stylize(source, target):
        asked.append(target)
        return source

    known = harness.known_styles_only(stylize, ["normal", "youthful"], "most.onnx")
    report = harness.evaluate({"most": known}, walks, pairs, *judges, progress=False)
    skipped = report["systems"]["most"]["skipped"]
    assert [s["target"] for s in skipped] == ["feminine"]
    assert skipped[0]["reason"] == "most.onnx was not trained on feminine"
    assert asked == ["youthful"] and report["systems"]["most"]["overall"]["pairs"] == 1


def test_identity_keeps_content_and_misses_the_style(report):
    identity = report["systems"]["identity"]["overall"]
    assert identity["content_accuracy"] >= 0.95
    assert identity["style_accuracy"] <= 0.1
    assert identity["content_consistency"] == pytest.approx(0.0, abs=1e-6)
    assert identity["jerk_ratio"] == pytest.approx(1.0)
    assert identity["foot_skating"] == pytest.approx(identity["foot_skating_input"])


def test_oracle_reaches_the_target_style(report):
    oracle = report["systems"]["oracle"]["overall"]
    assert oracle["style_accuracy"] >= 0.9
    assert oracle["content_accuracy"] >= 0.9
    assert oracle["content_consistency"] > 0.0  # another take is not the same motion


def test_oracle_is_closer_to_the_target_styles_than_identity(report):
    per_style = {n: s["per_style"] for n, s in report["systems"].items()}
    styles = report["settings"]["styles"]
    closer = [per_style["oracle"][s]["fmd"] < per_style["identity"][s]["fmd"] for s in styles]
    assert sum(closer) >= len(styles) - 1


def test_report_has_every_field(report, tmp_path):
    json_path, png_path = harness.write(report, tmp_path, model="identity")
    data = json.loads(json_path.read_text())
    assert png_path.stat().st_size > 10_000
    assert data["model"] == "identity"
    assert data["settings"]["pairs"] == report["systems"]["identity"]["overall"]["pairs"]
    for name in ("identity", "oracle"):
        system = data["systems"][name]
        assert set(system["overall"]) == {*harness.METRICS, "pairs"}
        assert set(system["per_style"]) == set(data["settings"]["styles"])
        for row in system["per_style"].values():
            assert set(row) == {*harness.METRICS, "pairs"} and row["fmd"] >= 0
        assert {"source", "content", "source_style", "target_style", "judged_style",
                "judged_content", *[k for k in harness.METRICS if k != "fmd"]} == set(system["pairs"][0])
    table = harness.format_table(report, model="identity")
    assert "identity (model)" in table and "FMD youthful" in table


def test_a_stylizer_off_the_canonical_skeleton_is_a_clear_error(clips, judges):
    sk = cmu31()
    wrong = Motion.from_rotations(sk, rot.identity((30, sk.n_joints)), np.zeros((30, 3)), 120.0)
    source = clips[0][0]
    pairs = [harness.Pair(source, "normal" if source.style != "normal" else "elderly")]
    with pytest.raises(MotionStyleError, match="canonical"):
        harness.evaluate({"bad": lambda m, s: wrong}, clips[:20], pairs, *judges, progress=False)


def test_cli_writes_the_report_and_prints_the_baselines(datasets, tmp_path):
    env = {**os.environ, "MOTION_STYLE_DATASETS": str(datasets)}
    out = subprocess.run(
        [sys.executable, "-m", "motion_style_ros.cli.main", "eval", "--pairs-per-cell", "1",
         "--out", str(tmp_path), "--quiet"],
        capture_output=True, text=True, env=env, timeout=600,
    )
    assert out.returncode == 0, out.stderr
    assert (tmp_path / "report.png").stat().st_size > 10_000
    data = json.loads((tmp_path / "report.json").read_text())
    assert set(data["systems"]) == {"identity", "oracle"}
    rows = data["systems"]["identity"]["pairs"]
    cells = {(r["content"], r["source_style"]) for r in rows}
    assert len({r["source"] for r in rows}) == len(cells)  # one take per cell
    assert len(rows) == data["settings"]["pairs"] == 6 * len(cells)  # 7 styles: 6 targets each
    for label in ("style accuracy", "content consistency CC", "FMD elderly", "identity", "oracle"):
        assert label in out.stdout


def test_the_recurrent_stylizer_is_scored_through_its_streaming_session(clips, judges, tmp_path):
    """A random-weight model, so this checks the wiring, not the quality (the model card has that)."""
    from motion_style_ros.runtime.offline import stylizer

    styles = sorted({info.style for info, _ in clips})
    recurrent_model(tmp_path / "erd.onnx", styles)
    stylize = stylizer("recurrent", str(tmp_path / "erd.onnx"))
    walks = [c for c in clips if c[0].content == "walk"][:2]
    pairs = [harness.Pair(info, s) for info, _ in walks for s in ("elderly", "youthful")
             if s != info.style]
    report = harness.evaluate({"recurrent": stylize}, clips, pairs, *judges, progress=False)
    rows = report["systems"]["recurrent"]["pairs"]
    assert len(rows) == len(pairs) >= 2
    assert all(r["bone_length_error"] < 1e-6 for r in rows)  # outputs go through FK
    source = walks[0][1]
    out = stylize(source, "elderly")
    assert out.n_frames == source.n_frames and not np.allclose(out.rotations, source.rotations)


@pytest.mark.parametrize("flags, message", [
    (["--reference-codes", "--stylizer", "recurrent"], "--reference-codes scores backends that take reference clips"),
    (["--reference-codes"], "--reference-codes scores backends that take reference clips"),
    (["--same-content", "--stylizer", "stgcn"], "--same-content and --consistency go with --reference-codes"),
    (["--consistency", "--stylizer", "stgcn"], "--same-content and --consistency go with --reference-codes"),
])
def test_reference_code_flags_that_do_not_go_together_are_one_line(flags, message, tmp_path):
    out = subprocess.run([sys.executable, "-m", "motion_style_ros.cli.main", "eval", "--out", str(tmp_path),
                          *flags], capture_output=True, text=True, timeout=120)
    assert out.returncode == 2 and message in out.stderr and len(out.stderr.strip().splitlines()) == 1
