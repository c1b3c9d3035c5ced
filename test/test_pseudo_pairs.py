"""Pseudo-pairs for distillation: both sides conditioned as the stream session conditions the input,
frame for frame; a target is kept only where judge panel 1 recognises its style (the most confident
candidate wins) and its legs keep the input's posture as far as the style allows; the file round-trips and a bad one is one line; a Style-ERD step is held to the
targets, and the card names the clips (so 'eval --unseen' leaves them out) and CMU."""

import dataclasses

import numpy as np
import pytest

torch = pytest.importorskip("torch", reason="the trainers need torch: pip install '.[train]'")

from motion_style_ros.cli.main import main  # noqa: E402
from motion_style_ros.core import rotations as rot  # noqa: E402
from motion_style_ros.core.motion import Motion  # noqa: E402
from motion_style_ros.core.resample import resample  # noqa: E402
from motion_style_ros.errors import MotionStyleError  # noqa: E402
from motion_style_ros.evaluation import posture  # noqa: E402
from motion_style_ros.io.datasets import index_bandai, load_bandai  # noqa: E402
from motion_style_ros.io.resources import rotation_stats  # noqa: E402
from motion_style_ros.training import data as training_data  # noqa: E402
from motion_style_ros.training import pseudo_pairs  # noqa: E402
from motion_style_ros.training.command import PAIRS_DEFAULTS  # noqa: E402
from motion_style_ros.training.content import FRAME  # noqa: E402
from motion_style_ros.training.export import CMU_ACKNOWLEDGEMENT, licence_fields  # noqa: E402
from motion_style_ros.training.loop import card_record  # noqa: E402
from motion_style_ros.training.most import trainer as most_trainer  # noqa: E402
from motion_style_ros.training.recurrent import trainer  # noqa: E402
from motion_style_ros.training.saae import trainer as saae_trainer  # noqa: E402
from motion_style_ros.training.stgcn import trainer as stgcn_trainer  # noqa: E402
from motion_style_ros.training.unlabelled import conditioned, conditioning, sources  # noqa: E402

STYLES = ["active", "elderly", "exhausted", "feminine", "masculine", "normal", "youthful"]
SLACK = 10.0  # degrees of posture slack (train pairs --posture-slack)


@pytest.fixture(scope="module")
def walks(datasets):
    """A real Bandai dataset-2 walk of every style, at 30 fps."""
    infos = [i for i in index_bandai(datasets, datasets=(2,)) if i.split == "test" and i.content == "walk"]
    chosen = [next(i for i in infos if i.style == s) for s in STYLES]
    return {info.style: resample(m, 30.0) for info, m in load_bandai(chosen, progress=False)}


def _frames_of(take: Motion, source: Motion) -> Motion:
    """``take`` cut or looped to ``source``'s frame count (a stand-in stylizer's output)."""
    index = np.arange(source.n_frames) % take.n_frames
    return Motion(take.skeleton, take.rotations[index], take.positions[index], source.fps)


def _knees_bent(motion: Motion, degrees: float) -> Motion:
    """``motion`` with both knees bent ``degrees`` further (the canonical knee's hinge is its y axis)."""
    sk, rotations = motion.skeleton, motion.rotations.copy()
    turn = rot.from_axis_angle(np.array([0.0, 1.0, 0.0]), np.radians(degrees))
    for side in "LR":
        knee = sk.index(f"LowerLeg_{side}")
        rotations[:, knee] = rot.multiply(rotations[:, knee], turn)
    return Motion(sk, rotations, motion.positions, motion.fps)


@pytest.fixture(scope="module")
def pairs(walks):
    stylizers = {"real": lambda source, style: _frames_of(walks[style], source),
                 "bent": lambda source, style: _knees_bent(source, 12.0),
                 "identity": lambda source, style: source}
    return pseudo_pairs.make(("cmu:07_01",), [], STYLES, 30.0, progress=False, stylizers=stylizers,
                             speeds=(1.25,), posture_slack=SLACK)


def test_conditioning_applies_the_inputs_rolls_size_and_height_to_its_output(datasets):
    stats = rotation_stats()
    (_, clip), = sources("cmu:07_02", stats)
    low = resample(clip, 30.0)
    condition = conditioning(low, 30.0, stats)
    same = condition(low)
    assert np.array_equal(same.positions, conditioned(low, 30.0, stats).positions)
    # a translated copy keeps the offset: the output is placed by the input's origin, not its own
    pelvis = low.skeleton.pelvis
    positions = low.positions.copy()
    positions[:, pelvis, 0] += 0.5
    shifted = condition(Motion(low.skeleton, low.rotations, positions, low.fps))
    assert shifted.n_frames == same.n_frames
    offset = shifted.positions[:, pelvis] - same.positions[:, pelvis]
    # one offset, divided by the performer's size as the root's path is, at the same height
    assert np.allclose(offset, offset[0], atol=1e-9)
    assert 0.3 < offset[0, 0] < 0.8 and offset[0, 1] == pytest.approx(0.0, abs=1e-9)


def test_a_target_is_kept_only_where_panel_1_recognises_its_style(pairs):
    assert len(pairs.tried) == 2 * len(STYLES)  # the clip and its 1.25x copy
    kept = [row for row in pairs.tried if row["kept"]]
    assert len(kept) == len(pairs.styles) >= 1
    # real walks are recognised, but a Bandai performer's legs are not the CMU performer's: the
    # posture gate refuses some of them
    assert sum("real" in row["recognised_by"] for row in pairs.tried) >= len(pairs.tried) * 0.7
    assert any("real" in row["posture_refused"] for row in pairs.tried)
    for row in pairs.tried:
        assert (row["kept"] is None) == (set(row["recognised_by"]) <= set(row["posture_refused"]))
        assert row["kept"] is None or row["kept"] in set(row["recognised_by"]) - set(row["posture_refused"])
    # the input with its knees bent 12 degrees more (panel 1 still reads a normal walk) is refused
    # for the posture it loses, where the style allows none of it
    assert any("bent" in row["posture_refused"] for row in pairs.tried if row["style"] == "normal")
    assert ("normal", "bent") not in set(zip(pairs.styles, pairs.made_by))
    assert pairs.meta["posture_slack"] == SLACK
    # the identity restyles nothing: it can only be kept for the style panel 1 reads in the input
    assert len({s for s, m in zip(pairs.styles, pairs.made_by) if m == "identity"}) <= 1
    assert all(0.0 < p <= 1.0 for p in pairs.probability)
    for x, y in zip(pairs.inputs, pairs.targets):
        assert x.shape[0] == y.shape[0] and y.shape[1] == FRAME and np.isfinite(y).all()
    assert set(pairs.clips) == {"cmu 07_01"} and pairs.meta["judges"] == ["judge_style.onnx", "judge_content.onnx"]
    assert pairs.meta["sources"] == ["cmu 07_01"]  # every clip looked at, kept or not


def test_an_agreeing_judge_must_recognise_a_target_too_and_panel_2_may_not(walks, tmp_path):
    stylizers = {"real": lambda source, style: _frames_of(walks[style], source),
                 "identity": lambda source, style: source}
    alone = pseudo_pairs.make(("cmu:07_01",), [], STYLES, 30.0, progress=False, stylizers=stylizers)
    # panel 1's own style judge again: it agrees with itself, so the same targets are kept
    twice = pseudo_pairs.make(("cmu:07_01",), [], STYLES, 30.0, progress=False, stylizers=stylizers,
                              agree=("judge_style.onnx",))
    assert twice.made_by == alone.made_by and np.allclose(twice.probability, alone.probability)
    assert twice.meta["judges"] == ["judge_style.onnx", "judge_style.onnx", "judge_content.onnx"]
    with pytest.raises(MotionStyleError, match="panel 2's: it reports") as err:
        pseudo_pairs.make(("cmu:07_01",), [], STYLES, 30.0, progress=False, stylizers=stylizers,
                          agree=("judge2_style.onnx",))
    assert "\n" not in str(err.value)


def test_a_bend_is_kept_only_as_far_as_the_style_bends_real_performers(walks):
    source = walks["normal"]
    stance = posture.posture(source)
    crouch = _knees_bent(source, 30.0)
    assert posture.posture(crouch)["knee_mean"] == pytest.approx(stance["knee_mean"] + 30.0, abs=1.0)
    slack = SLACK
    assert posture.keeps(stance, source, "normal", {}, slack)
    assert not posture.keeps(stance, crouch, "normal", {}, slack)
    # a style that bends real performers' knees that far (and no further at the hips) allows it
    bent = {k: v - stance[k] for k, v in posture.posture(crouch).items()}
    assert posture.keeps(stance, crouch, "elderly", {"elderly": bent}, slack)
    assert not posture.keeps(stance, crouch, "youthful", {"elderly": bent}, slack)


def test_a_stylizer_that_changes_the_length_is_refused(walks):
    with pytest.raises(MotionStyleError, match="frame for frame"):
        pseudo_pairs.make(("cmu:07_01",), [], STYLES[:1], 30.0, progress=False,
                          stylizers={"short": lambda source, style: source[: source.n_frames // 2]})


def test_the_file_round_trips_and_a_bad_one_is_one_line(pairs, tmp_path):
    path = tmp_path / "pairs.npz"
    pseudo_pairs.save(pairs, path)
    back = pseudo_pairs.load(path)
    assert back.styles == pairs.styles and back.made_by == pairs.made_by and back.meta == pairs.meta
    assert all(np.array_equal(a, b) for a, b in zip(back.targets, pairs.targets))
    bad = tmp_path / "bad.npz"
    bad.write_bytes(b"not an npz at all")
    with pytest.raises(MotionStyleError, match="not a pseudo-pairs file") as err:
        pseudo_pairs.load(bad)
    assert "\n" not in str(err.value)


@pytest.mark.parametrize("module, sized", [
    (trainer, {"crop_frames": 8}), (most_trainer, {}), (stgcn_trainer, {}), (saae_trainer, {}),
    (saae_trainer, {"variant": "model1"})], ids=["recurrent", "most", "stgcn", "saae_model2", "saae_model1"])
def test_a_step_is_held_to_the_targets_and_the_card_names_the_clips(datasets, pairs, tmp_path, module, sized):
    path = tmp_path / "pairs.npz"
    # a second clip was looked at and none of its pairs kept: the card names it all the same
    pseudo_pairs.save(dataclasses.replace(pairs, meta={**pairs.meta, "sources": ["cmu 07_01", "cmu 07_02"]}), path)
    labelled = training_data.load_data((2,), progress=False, root=datasets, takes_per_cell=1)
    cfg = module.tiny_config(distil=str(path), **sized)
    data = training_data.with_pairs(labelled, cfg.distil)
    assert len(data.pairs.features) == len(pairs.styles)
    runs = {}
    for key, d, c in (("with", data, cfg), ("without", labelled, module.tiny_config(**sized))):
        run = module.Trainer(c, d, tmp_path / key, progress=False)
        run.run(iterations=2, log_every=1, val_every=1000)
        runs[key] = run
    terms = runs["with"].step(2)
    assert terms["distil"] > 0 and "distil" not in runs["without"].step(2)
    assert any(not torch.equal(a, b) for a, b in zip(runs["with"].model.parameters(),
                                                      runs["without"].model.parameters()))
    record = card_record(runs["with"], data, 0.0, "", None)
    assert record["clips"]["unlabelled"] == ["cmu 07_01", "cmu 07_02"]
    assert record["clips"]["pairs"]["kept"] == len(pairs.styles) and "distilled" in record
    assert CMU_ACKNOWLEDGEMENT in licence_fields({**record, "config": {}})["attribution"]


def test_a_run_given_clips_makes_their_pairs_once_into_its_folder(pairs, tmp_path):
    """``--distil CLIPS``: the pairs are made as ``train pairs`` makes them by default, and a resumed
    run reads them again instead of making them anew; other clips make new pairs; a file is used as
    it is, and a missing one is one line."""
    calls = []

    def made(specs, candidates, styles, fps, threads, progress, speeds, mirror, parts, posture_slack, agree):
        assert parts == folder / "pairs.npz.parts" and posture_slack == PAIRS_DEFAULTS["posture_slack"]
        assert agree == PAIRS_DEFAULTS["agree"]
        parts.mkdir(parents=True, exist_ok=True)  # what a making leaves until its file is written
        calls.append((specs, [str(c) for c in candidates], speeds, mirror))
        return dataclasses.replace(pairs, meta={**pairs.meta, "clips": list(specs), "posture_slack": posture_slack,
                                                "agree": list(agree)})

    folder = tmp_path / "most_5"
    first = pseudo_pairs.for_run("cmu:07_01", folder, 30.0, progress=False, make_pairs=made)
    assert first == str(folder / "pairs.npz") and len(pseudo_pairs.load(first).styles) == len(pairs.styles)
    assert not (folder / "pairs.npz.parts").exists()
    assert calls == [(("cmu:07_01",), PAIRS_DEFAULTS["candidates"].split(","), (0.8, 1.25), True)]
    assert pseudo_pairs.for_run("cmu:07_01", folder, 30.0, make_pairs=made) == first and len(calls) == 1
    pseudo_pairs.for_run("cmu:07_01,cmu:02_01", folder, 30.0, progress=False, make_pairs=made)
    assert len(calls) == 2 and pseudo_pairs.load(first).meta["clips"] == ["cmu:07_01", "cmu:02_01"]
    # pairs made with a posture gate or without the agreeing judges (not the default) are made again
    pseudo_pairs.save(dataclasses.replace(pairs, meta={**pairs.meta, "clips": ["cmu:07_01"]}), folder / "pairs.npz")
    pseudo_pairs.for_run("cmu:07_01", folder, 30.0, progress=False, make_pairs=made)
    assert len(calls) == 3 and pseudo_pairs.load(first).meta["posture_slack"] is None
    assert pseudo_pairs.for_run(first, tmp_path / "other", 30.0, make_pairs=made) == first and len(calls) == 3
    with pytest.raises(MotionStyleError, match="no pairs file .*nope.npz"):
        pseudo_pairs.for_run(str(tmp_path / "nope.npz"), folder, 30.0, make_pairs=made)


class _Stopped(Exception):
    pass


def test_a_stopped_making_goes_on_where_it_stopped(tmp_path):
    calls, stop = [], [len(STYLES) + 2]  # once, two styles into the second clip

    def identity(source, style):
        calls.append(style)
        if len(calls) in stop:
            stop.clear()
            raise _Stopped
        return source

    parts = tmp_path / "pairs.npz.parts"

    def made(styles=STYLES, kept=True):
        return pseudo_pairs.make(("cmu:07_01",), [], styles, 30.0, progress=False, stylizers={"identity": identity},
                                 speeds=(1.25,), parts=parts if kept else None)

    with pytest.raises(_Stopped):
        made()
    assert [p.name for p in parts.iterdir()] == ["00000.npz"]  # the first clip, whole
    calls.clear()
    resumed = made()
    assert len(calls) == len(STYLES)  # only the second clip is stylized again
    calls.clear()
    whole = made(kept=False)
    assert resumed.tried == whole.tried and resumed.made_by == whole.made_by and resumed.meta == whole.meta
    assert all(np.array_equal(a, b) for a, b in zip(resumed.targets, whole.targets))
    calls.clear()
    made(STYLES[:3])  # other settings: nothing kept is used
    assert len(calls) == 2 * 3


def test_the_plain_saae_has_no_style_input_to_distil_into(datasets, pairs, tmp_path):
    path = tmp_path / "pairs.npz"
    # a second clip was looked at and none of its pairs kept: the card names it all the same
    pseudo_pairs.save(dataclasses.replace(pairs, meta={**pairs.meta, "sources": ["cmu 07_01", "cmu 07_02"]}), path)
    labelled = training_data.load_data((2,), progress=False, root=datasets, takes_per_cell=1)
    data = training_data.with_pairs(labelled, str(path))
    with pytest.raises(MotionStyleError, match="plain SAAE has no style input.*model1 and model2 have"):
        saae_trainer.Trainer(saae_trainer.tiny_config(variant="saae", distil=str(path)), data, tmp_path)


def test_pairs_into_a_style_the_model_lacks_are_refused(datasets, pairs, tmp_path):
    path = tmp_path / "pairs.npz"
    pseudo_pairs.save(pairs, path)
    left_out = next(s for s in pairs.styles if s != "normal")
    labelled = training_data.load_data((2,), progress=False, root=datasets, takes_per_cell=1,
                                       exclude=(left_out,))
    with pytest.raises(MotionStyleError, match=f"pairs into {left_out}, which the model does not have"):
        training_data.with_pairs(labelled, str(path))


def test_bad_pairs_flags_are_one_line(capsys, tmp_path):
    assert main(["train", "most", "--distil", str(tmp_path / "p.npz"), "--out", str(tmp_path)]) == 2
    assert "no pairs file" in capsys.readouterr().err
    assert main(["train", "pairs", "--clips", "cmu:07", "--speeds", "-1", "--out", str(tmp_path / "p.npz")]) == 2
    assert "--speeds takes positive numbers" in capsys.readouterr().err
    assert main(["train", "pairs", "--clips", "cmu:07", "--posture-slack", "-5", "--out", str(tmp_path / "p.npz")]) == 2
    assert "--posture-slack takes degrees" in capsys.readouterr().err
    assert main(["train", "pairs", "--clips", "cmu:07", "--candidates", "nope", "--out", str(tmp_path / "p.npz")]) == 2
    assert "nope" in capsys.readouterr().err
    assert main(["train", "pairs", "--clips", "cmu:07", "--agree", "judge9_style.onnx", "--out", str(tmp_path / "p.npz")]) == 2
    assert "judge9_style.onnx" in capsys.readouterr().err
    assert main(["train", "pairs", "--clips", "cmu:07", "--agree", "judge2_style.onnx", "--out", str(tmp_path / "p.npz")]) == 2
    assert "panel 2's" in capsys.readouterr().err
