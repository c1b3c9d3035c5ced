"""Unlabelled training clips (other capture setups): conditioned as a live stream is before the
model sees it, with their augmentation, recorded on the card; a Style-ERD step restyles them; a
bad spec is one line."""

import numpy as np
import pytest

torch = pytest.importorskip("torch", reason="the trainers' data needs torch: pip install '.[train]'")

from motion_style_ros.core.motion import Motion
from motion_style_ros.core.proportions import clip_scale
from motion_style_ros.errors import MotionStyleError
from motion_style_ros.io.datasets import index_bandai, load_bandai
from motion_style_ros.io.resources import rotation_stats
from motion_style_ros.training import data as training_data
from motion_style_ros.training import recurrent, stgcn
from motion_style_ros.training.loop import card_record
from motion_style_ros.training.unlabelled import conditioned, load_unlabelled, sources


@pytest.fixture(scope="module")
def walk(datasets):
    info = next(i for i in index_bandai(datasets, datasets=(2,)) if i.split == "val" and i.content == "walk")
    (_, motion), = load_bandai([info], progress=False)
    return motion


@pytest.mark.parametrize("size", [0.8, 1.25])
def test_a_larger_or_smaller_performer_is_brought_to_the_training_size(walk, size):
    reference = float(rotation_stats()["scale_reference"])
    root = walk.positions[:, walk.skeleton.pelvis]
    other = Motion.from_rotations(walk.skeleton, walk.rotations, root[:1] + (root - root[:1]) * size, 120.0)
    out = conditioned(other, 30.0, rotation_stats())
    assert out.fps == 30.0 and out.n_frames == pytest.approx(walk.n_frames / 4, abs=1)
    assert clip_scale(other, reference) == pytest.approx(size * clip_scale(walk, reference), rel=0.1)
    assert clip_scale(out, reference) == pytest.approx(1.0, abs=0.08)


def test_cmu_subject_clips_with_their_speed_and_mirrored_copies(datasets):
    names = [n for n, _ in sources("cmu:07", rotation_stats())]
    assert len(names) == 12 and names[0] == "cmu 07_01"
    plain, _ = load_unlabelled(("cmu:07",), 30.0, progress=False)
    features, listed = load_unlabelled(("cmu:07",), 30.0, speeds=(0.8,), mirror=True, progress=False)
    assert listed == names and len(features) == 4 * len(plain)
    assert len(features[1]) == pytest.approx(len(plain[0]) / 0.8, abs=2)  # the 0.8 copy
    assert np.isfinite(np.concatenate(features)).all()


@pytest.mark.parametrize("spec", ["cmu:99", "/nonexistent/folder"])
def test_a_spec_naming_nothing_is_one_line(datasets, spec):
    with pytest.raises(MotionStyleError, match=spec) as err:
        load_unlabelled((spec,), 30.0, progress=False)
    assert "\n" not in str(err.value)


@pytest.mark.parametrize("trainer", [recurrent, stgcn], ids=["style_erd", "stgcn"])
def test_a_step_restyles_the_unlabelled_windows_and_the_card_lists_them(datasets, tmp_path, trainer):
    labelled = training_data.load_data((2,), progress=False, root=datasets, takes_per_cell=1)
    cfg = trainer.tiny_config(unlabelled=("cmu:07",))
    features, names = load_unlabelled(cfg.unlabelled, 30.0, progress=False)
    unknown = np.full(len(features), -1)
    data = training_data.Data(labelled.styles, labelled.contents, labelled.splits,
                              training_data.Clips(features, unknown, unknown), tuple(names))
    runs = {}
    for key, d in (("with", data), ("without", labelled)):
        run = trainer.Trainer(cfg, d, tmp_path / key, progress=False)
        run.run(iterations=3, log_every=1, val_every=1000)
        runs[key] = run
    with_u, without = runs["with"], runs["without"]
    # the same labelled windows and seeds: only the restyled unlabelled windows differ
    assert any(not torch.equal(a, b) for a, b in zip(with_u.model.parameters(), without.model.parameters()))
    assert all(torch.isfinite(p).all() for p in with_u.model.parameters())
    assert card_record(with_u, data, 0.0, "", None)["clips"]["unlabelled"] == names
    assert "unlabelled" not in card_record(without, labelled, 0.0, "", None)["clips"]


def test_a_model_trained_with_cmu_clips_acknowledges_cmu_in_its_card():
    from motion_style_ros.training.export import CMU_ACKNOWLEDGEMENT, LICENCE, licence_fields

    assert licence_fields({"config": {"unlabelled": []}}) == LICENCE
    fields = licence_fields({"config": {"unlabelled": ["cmu:07", "/data/studio"]}})
    assert fields["licence"] == LICENCE["licence"]
    assert fields["attribution"].startswith(LICENCE["attribution"]) and CMU_ACKNOWLEDGEMENT in fields["attribution"]
