"""Offline stylizing: `motion-style stylize` on a real BVH file and the unseen-input checks."""

import subprocess
import sys

import numpy as np
import pytest
from onnx_fixtures import recurrent_model, windowed_model

from motion_style_ros.core import rotations as rot
from motion_style_ros.core.synthetic import synthetic_motion
from motion_style_ros.evaluation import unseen
from motion_style_ros.io import bvh

STYLES = ["active", "elderly", "normal"]


@pytest.fixture(scope="module")
def model(tmp_path_factory):
    return recurrent_model(tmp_path_factory.mktemp("erd") / "erd.onnx", STYLES)


def stylize_cli(*args):
    return subprocess.run([sys.executable, "-m", "motion_style_ros.cli.main", "stylize", *map(str, args)],
                          capture_output=True, text=True, timeout=300)


def test_stylize_retargets_a_cmu_clip_and_writes_one_canonical_bvh_per_style(model, datasets, tmp_path):
    source = datasets / "cmu/data/07/07_01.bvh"
    out = stylize_cli(source, "-o", tmp_path / "walk.bvh", "--model", model, "--style", "elderly",
                      "--style", "active", "--render", tmp_path / "walk.png")
    assert out.returncode == 0, out.stderr
    frames = bvh.read(source).to_motion().n_frames
    results = [bvh.read(tmp_path / f"walk_{s}.bvh").to_motion() for s in ("elderly", "active")]
    for result in results:
        assert result.skeleton.names[1] == "Hips" and result.n_frames == frames
        assert np.isfinite(result.rotations).all()
    assert not np.allclose(results[0].rotations, results[1].rotations)
    assert (tmp_path / "walk.png").stat().st_size > 10_000


def test_stylize_errors_are_one_line(model, tmp_path):
    bad_style = stylize_cli(tmp_path / "none.bvh", "-o", tmp_path / "o.bvh", "--model", model,
                            "--style", "proud")
    assert bad_style.returncode == 2 and len(bad_style.stderr.strip().splitlines()) == 1
    (tmp_path / "bad.bvh").write_text("HIERARCHY\nROOT Hips\n{\n")
    bad_file = stylize_cli(tmp_path / "bad.bvh", "-o", tmp_path / "o.bvh", "--model", model,
                           "--style", "elderly")
    assert bad_file.returncode == 2 and "bad.bvh" in bad_file.stderr
    assert len(bad_file.stderr.strip().splitlines()) == 1


def test_stylize_with_a_reference_clip_on_the_stgcn_backend(datasets, tmp_path):
    """A Bandai take (canonical skeleton, centimetres) in; the style code from another take."""
    model = windowed_model(tmp_path / "stgcn.onnx", ["active", "elderly", "exhausted", "feminine",
                                                     "masculine", "normal", "youthful"])
    data = datasets / "bandai-namco/Bandai-Namco-Research-Motiondataset-2/data"
    source, reference = data / "dataset-2_walk_normal_001.bvh", data / "dataset-2_walk_elderly_001.bvh"
    outputs = {}
    for seed in (0, 1):
        out = stylize_cli(source, "-o", tmp_path / f"ref{seed}.bvh", "--backend", "stgcn", "--model", model,
                          "--reference", reference, "--seed", seed)
        assert out.returncode == 0, out.stderr
        assert "style read as" in out.stdout
        outputs[seed] = bvh.read(tmp_path / f"ref{seed}.bvh").to_motion(scale=0.01)
    hips = outputs[0].global_positions()[:, 1]
    assert 0.7 < np.median(hips[:, 1]) < 1.1  # metres in, centimetres out: a standing pelvis height
    # the reference's code replaces the seed's for its style: the seed no longer matters
    assert np.allclose(outputs[0].rotations, outputs[1].rotations)
    recurrent = stylize_cli(source, "-o", tmp_path / "r.bvh", "--reference", reference)
    assert recurrent.returncode == 2 and "needs --backend stgcn" in recurrent.stderr
    assert len(recurrent.stderr.strip().splitlines()) == 1


def test_unseen_checks_catch_nan_and_flips():
    walk = synthetic_motion("walk", 30.0, 2.0)
    clean = unseen.check(walk, walk)
    assert clean["finite"] and clean["flips"] == 0 and clean["foot_skating_ratio"] == pytest.approx(1.0)
    flipped = walk.rotations.copy()
    knee = walk.skeleton.index("LowerLeg_L")
    flipped[30:, knee] = rot.multiply(rot.from_axis_angle(np.array([1.0, 0, 0]), np.pi * 0.9),
                                      flipped[30:, knee])
    bad = unseen.check(walk, type(walk).from_rotations(walk.skeleton, flipped, walk.positions[:, 1], 30.0))
    assert bad["flips"] == 1 and bad["largest_joint_step_deg"] > unseen.FLIP_DEGREES
    nan = flipped.copy()
    nan[5] = np.nan
    assert not unseen.check(walk, type(walk).from_rotations(walk.skeleton, nan, walk.positions[:, 1], 30.0))["finite"]


def test_unseen_clips_leave_out_what_a_model_trained_on_and_recognition_is_split_by_source(datasets):
    from motion_style_ros.evaluation.judges import Judge

    every = unseen.neutral_clips(datasets)
    kept = unseen.neutral_clips(datasets, leave_out=("cmu 02_01", "cmu 02_02"))
    assert len(kept) == len(every) - 2 and not any(t.startswith(("cmu 02_01 ", "cmu 02_02 ")) for t, _ in kept)
    assert {unseen.capture_setup(t) for t, _ in every} == {"cmu 02", "cmu 07", "xia"}
    # the input itself as the output: recognised where the judge reads the clip as the target
    clips = [every[0], every[-1]]
    judge = Judge("style")
    report = unseen.evaluate(lambda m, s: m, ["normal", "elderly"], clips, [judge], rates=(), progress=False)
    by_source = report["summary"]["style_recognised_1_by_source"]
    assert set(by_source) == {"cmu 02", "xia"}
    rows = [r for r in report["rows"] if unseen.capture_setup(r["clip"]) == "xia"]
    assert by_source["xia"] == np.mean([r["judged_style_1"] == r["style"] for r in rows])
    # among the stylizer's two styles: the likelier of the two, whatever else the judge reads
    for clip_title, clip in clips:
        p = judge.judge([clip]).probabilities[0]
        likelier = max(["normal", "elderly"], key=lambda s: p[judge.labels.index(s)])
        for r in report["rows"]:
            if r["clip"] == clip_title:
                assert r["recognised_1_among_styles"] == (r["style"] == likelier)
                assert r["recognised_1_among_styles"] >= r["recognised_1"]  # a judged target stays one
    assert report["summary"]["style_recognised_1_among_styles"] == 0.5  # one of two styles per clip


def test_the_all_styles_model_offers_every_bandai_style_and_restyles_into_one_of_dataset_1(datasets, tmp_path):
    """``style_erd_22.onnx``: both Bandai sets' styles (a dataset-1 style named like a dataset-2 one
    with -d1), each reachable from the command line."""
    from motion_style_ros.io.datasets import index_bandai, style_label
    from motion_style_ros.runtime.onnx_model import model_path, read_card

    card = read_card(model_path("style_erd_22.onnx"))
    labels = {style_label(i.dataset, i.style) for i in index_bandai(datasets)}
    assert set(card["styles"]) == labels and len(labels) == 22
    source = datasets / "cmu/data/07/07_01.bvh"
    out = stylize_cli(source, "-o", tmp_path / "walk.bvh", "--model", "style_erd_22.onnx", "--style", "happy")
    assert out.returncode == 0, out.stderr
    clip = bvh.read(tmp_path / "walk.bvh")
    assert np.isfinite(clip.data).all() and clip.n_frames > 100
