"""A user's labelled BVH folder (issue 23): built in tmp_path from a few Bandai and CMU clips (links to
the datasets fixture, never committed) under style folders and through a labels.csv, with bad files;
indexed, cached and split beside it, every trainer run on it for a few iterations, its exports
streamed through the runtime's sessions; the device flag; torchrun with gloo against one process."""

import json
import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from motion_style_ros.errors import MotionStyleError
from motion_style_ros.io import user_data

BANDAI = "bandai-namco/Bandai-Namco-Research-Motiondataset-2/data/dataset-2_{}_{}_{:03d}.bvh"
CMU = ("02/02_01.bvh", "02/02_02.bvh", "07/07_01.bvh")  # walks from another studio and rig (120 fps)


def _clips(datasets):
    """``(style, content, source)`` of the folder's takes: 3 elderly and 3 normal Bandai walks, 3 CMU."""
    takes = [(style, "walk", datasets / BANDAI.format("walk", style, t))
             for style in ("elderly", "normal") for t in (1, 2, 3)]
    return takes + [("casual", "walk", datasets / "cmu" / "data" / c) for c in CMU]


def _bad_files(where):
    """A text file named .bvh and a truncated BVH: skipped, one line each."""
    (where / "notes.bvh").write_text("not motion\n")
    whole = next(p for p in where.parent.rglob("*.bvh") if p.is_symlink()).read_bytes()
    (where / "cut.bvh").write_bytes(whole[: len(whole) // 3])


@pytest.fixture(scope="module")
def env(tmp_path_factory):
    """The cache in a temporary folder (for this module and the processes it starts)."""
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("MOTION_STYLE_CACHE", str(tmp_path_factory.mktemp("cache")))
        yield dict(os.environ)


@pytest.fixture(scope="module")
def folder(datasets, tmp_path_factory, env):
    """Style folders (as 100STYLE ships): PATH/<style>/<file>.bvh, and two bad files."""
    root = tmp_path_factory.mktemp("styles")
    for style, _, source in _clips(datasets):
        (root / style).mkdir(exist_ok=True)
        (root / style / source.name).symlink_to(source)
    _bad_files(root / "normal")
    return root


@pytest.fixture(scope="module")
def labelled(datasets, tmp_path_factory, env):
    """Flat files labelled by labels.csv (file, style, content), one listed file missing, one not listed."""
    root = tmp_path_factory.mktemp("csv")
    rows = ["file,style,content"]
    for style, content, source in _clips(datasets):
        (root / source.name).symlink_to(source)
        rows.append(f"{source.name},{style},{content}")
    (root / "unlisted.bvh").symlink_to(_clips(datasets)[0][2])
    rows.append("gone.bvh,normal,walk")
    (root / "labels.csv").write_text("\ufeff" + "\n".join(rows) + "\n")  # as a spreadsheet saves it
    return root


def test_style_folders_are_indexed_split_beside_the_data_and_bad_files_skipped(folder, caplog):
    first = user_data.load_folder(folder, progress=False)
    assert len(first.infos) == 9 and first.build_seconds is not None
    assert sorted(p.split(":")[0] for p in first.problems) == [str(folder / "normal" / n)
                                                                for n in ("cut.bvh", "notes.bvh")]
    assert all(m.fps == 30 and m.skeleton.n_joints == 22 for m in first.motions)
    splits = {(i.style, i.split) for i in first.infos}
    assert splits == {(s, p) for s in ("casual", "elderly", "normal") for p in ("train", "val", "test")}
    written = (folder / user_data.SPLIT).read_text().splitlines()
    assert written[0] == "file,split" and len(written) == 10
    assert first.too_few() == {}

    caplog.clear()
    again = user_data.load_folder(folder, progress=False)  # from the cache, the split read back
    assert again.build_seconds is None and [i.split for i in again.infos] == [i.split for i in first.infos]
    assert len([r for r in caplog.records if r.levelname == "WARNING"]) == 2  # the skipped files again
    np.testing.assert_array_equal(again.motions[0].rotations, first.motions[0].rotations)


def test_a_take_added_after_the_split_is_refused_and_small_styles_are_reported(folder, tmp_path, env):
    user_data.load_folder(folder, progress=False)  # writes the split
    copy = tmp_path / "copy"
    copy.mkdir()
    for path in folder.rglob("*.bvh"):
        (copy / path.relative_to(folder)).parent.mkdir(exist_ok=True)
        (copy / path.relative_to(folder)).symlink_to(path.resolve())
    (copy / user_data.SPLIT).write_text((folder / user_data.SPLIT).read_text())
    (copy / "casual" / "02_01.bvh").rename(copy / "casual" / "02_01_again.bvh")
    with pytest.raises(MotionStyleError, match="no split for 1 take.*casual/02_01_again.bvh.*delete it"):
        user_data.load_folder(copy, progress=False)

    (copy / user_data.SPLIT).unlink()
    (copy / "casual" / "02_01_again.bvh").unlink()
    assert user_data.load_folder(copy, progress=False).too_few() == {"casual": 2}
    out = subprocess.run([sys.executable, "-m", "motion_style_ros.cli.main", "data", "index", "--dataset",
                          str(copy)], check=False, capture_output=True, text=True, env=env)
    assert out.returncode == 0, out.stderr
    assert "style 'casual' has 2 take(s); training needs at least 3" in out.stdout
    assert "Traceback" not in out.stderr and out.stderr.count("skipped") == 2


def test_labels_csv_names_styles_and_contents(labelled):
    found = user_data.load_folder(labelled, progress=False)
    assert sorted({(i.style, i.content) for i in found.infos}) == [
        ("casual", "walk"), ("elderly", "walk"), ("normal", "walk")]
    assert len(found.infos) == 9 and len(found.problems) == 2
    assert {p.split(": ")[1] for p in found.problems} == {
        "listed in labels.csv but not a .bvh file in the folder; skipped", "not listed in labels.csv; skipped"}


def test_cli_cache_and_a_missing_folder(folder, env, tmp_path):
    run = [sys.executable, "-m", "motion_style_ros.cli.main", "data"]
    out = subprocess.run([*run, "cache", "--dataset", str(folder)], check=False, capture_output=True, text=True, env=env)
    assert out.returncode == 0 and "up to date" in out.stdout and "9 takes" in out.stdout, out
    bad = subprocess.run([*run, "index", "--dataset", str(tmp_path / "nowhere")], check=False, capture_output=True,
                         text=True, env=env)
    assert bad.returncode == 2 and len(bad.stderr.strip().splitlines()) == 1
    assert "nor a folder" in bad.stderr


# --- training on it ---------------------------------------------------------------------------------


@pytest.fixture
def torch():
    """Torch, or the test skipped (the folder's tests above run without it)."""
    return pytest.importorskip("torch", reason="trains models: pip install '.[train]'")


def test_a_style_with_too_few_takes_is_refused_before_training(folder, tmp_path, torch):
    from motion_style_ros.training import data

    small = tmp_path / "small"
    for path in folder.rglob("*.bvh"):
        if path.is_symlink() and path.name != "02_01.bvh":
            (small / path.parent.name).mkdir(parents=True, exist_ok=True)
            (small / path.parent.name / path.name).symlink_to(path.resolve())
    with pytest.raises(MotionStyleError, match=r"too few takes in style\(s\) casual \(2\).*--exclude-styles"):
        data.load_data(folder=small, progress=False)
    assert data.load_data(folder=small, progress=False, exclude=("casual",)).styles == ("elderly", "normal")


@pytest.fixture(scope="module")
def clip(folder):
    """A CMU test take of the folder, retargeted: what the exports are streamed on."""
    found = user_data.load_folder(folder, progress=False)
    return next(m for i, m in zip(found.infos, found.motions) if i.style == "casual" and i.split == "test")


def _stream(backend, path, clip, style):
    from motion_style_ros.runtime.backends import BACKENDS

    session = BACKENDS[backend].session_class()(str(path), input_fps=clip.fps)
    out = session.run(clip, style)
    assert out.n_frames == clip.n_frames and np.isfinite(out.rotations).all()
    return out


@pytest.mark.parametrize("backend", ["recurrent", "stgcn"])
def test_each_stylizer_trains_on_the_folder_exports_and_streams(backend, folder, clip, tmp_path, torch):
    from motion_style_ros.training import recurrent, stgcn

    module = {"recurrent": recurrent, "stgcn": stgcn}[backend]
    cfg = module.tiny_config(data=str(folder), neutral="casual")  # the CMU walks as the neutral style
    card = module.train(cfg, tmp_path / "models", iterations=3, checkpoints=tmp_path / "ckpt",
                        progress=False, licence="CC0, the studio's own captures", device="cpu")
    assert card["styles"] == ["casual", "elderly", "normal"] and card["neutral_style"] == "casual"
    assert card["licence"] == "CC0, the studio's own captures" and str(folder) in card["attribution"]
    assert card["training"]["clips"] == {"train": 3, "val": 3}
    assert card["training"]["history"]["iterations"] == 3
    if backend == "recurrent":  # one content (style folders): no content network to train
        assert card["training"]["history"]["content_network"]["iterations"] == 0
    _stream(backend, tmp_path / "models" / f"{card['name']}.onnx", clip, "elderly")


def test_the_judges_train_on_the_folder_and_judge_its_takes(folder, clip, tmp_path, torch):
    from motion_style_ros.evaluation.judges import Judge
    from motion_style_ros.training import judges

    cfg = judges.Config(kind="style", data=str(folder), epochs=1, crops_per_epoch=32, batch=16)
    card = judges.train(cfg, tmp_path, checkpoints=tmp_path / "ckpt", progress=False)
    assert card["labels"] == ["casual", "elderly", "normal"] and card["licence"] == "as the user's data"
    assert card["accuracy"]["test_clips"] == 3
    judged = Judge(tmp_path / "judge_style.onnx").judge([clip])
    assert judged.labels[0] in card["labels"] and judged.probabilities.shape == (1, 3)


def test_eval_scores_a_model_of_the_folder_on_its_held_out_takes_with_its_judges(folder, tmp_path, env, torch):
    from motion_style_ros.training import judges, recurrent

    models = tmp_path / "models"
    recurrent.train(recurrent.tiny_config(data=str(folder)), models, iterations=2, checkpoints=tmp_path / "ckpt",
                    progress=False)
    for kind in ("style", "content"):
        judges.train(judges.Config(kind=kind, data=str(folder), epochs=1, crops_per_epoch=32, batch=16), models,
                     checkpoints=tmp_path / "ckpt", progress=False)
    run = [sys.executable, "-m", "motion_style_ros.cli.main", "eval", "--data", str(folder), "--quiet",
           "--stylizer", "recurrent", "--model", str(models / "style_erd.onnx"), "--out", str(tmp_path / "eval")]
    out = subprocess.run([*run, "--judges", str(models)], check=False, capture_output=True, text=True, env=env)
    assert out.returncode == 0, out.stderr[-12000:]
    report = json.loads((tmp_path / "eval" / "report.json").read_text())
    assert report["settings"]["test_clips"] == 3 and report["settings"]["styles"] == ["casual", "elderly", "normal"]
    assert str(folder) in report["settings"]["data"]
    for name in ("recurrent", "identity", "oracle"):  # each test take into the two other styles
        assert report["systems"][name]["overall"]["pairs"] == 6
    assert report["systems"]["oracle"]["overall"]["content_accuracy"] is not None
    alone = subprocess.run(run, check=False, capture_output=True, text=True, env=env)
    assert alone.returncode == 2 and "--data and --judges go together" in alone.stderr


def test_a_device_that_is_not_there_is_one_line(folder, tmp_path, env, torch):
    from motion_style_ros.training import hardware

    missing = next(d for d in ("cuda", "mps") if d not in hardware.available())
    out = subprocess.run([sys.executable, "-m", "motion_style_ros.cli.main", "train", "recurrent", "--data",
                          str(folder), "--out", str(tmp_path), "--device", missing],
                         check=False, capture_output=True, text=True, env=env)
    assert out.returncode == 2 and len(out.stderr.strip().splitlines()) == 1, out.stderr
    assert f"--device {missing}: not available on this machine" in out.stderr
    assert f"available: {', '.join(hardware.available())}" in out.stderr


# --- several processes ------------------------------------------------------------------------------

_RUN = """
import sys
from pathlib import Path

from motion_style_ros.training import recurrent, stgcn

model, folder, checkpoints, iterations = sys.argv[1:]
module = {"recurrent": recurrent, "stgcn": stgcn}[model]
module.train(module.tiny_config(data=folder, batch=8), Path(checkpoints) / "models", iterations=int(iterations),
             checkpoints=Path(checkpoints), threads=1, progress=False, log_every=1, device="cpu", resume=True)
"""
# what each trainer checkpoints, and its exported file
_PARTS = {"recurrent": (("model", "dis", "ema"), "style_erd.onnx"),
          "stgcn": (("gen", "mapping", "encoder", "dis", "gen_ema"), "stgcn.onnx")}


@pytest.mark.parametrize("model", ["recurrent", "stgcn"])
def test_torchrun_with_gloo_follows_one_process_with_the_whole_batch_and_resumes_in_one(model, folder, tmp_path,
                                                                                        env, torch):
    """2 processes of 4 windows each against 1 of 8, 6 iterations: the same train losses (2e-5, the
    log keeps 5 decimals) and weights (1e-3: Adam turns float rounding in near-zero gradients into
    steps of up to its learning rate; measured 1.1e-6 for Style-ERD, 1.5e-4 for ST-GCN), and the
    2-process checkpoint continued in one process as the one-process run continues."""
    script = tmp_path / "run.py"
    script.write_text(textwrap.dedent(_RUN))
    env = {**env, "OMP_NUM_THREADS": "1"}
    parts, exported = _PARTS[model]
    from motion_style_ros.training import data

    def run_folder(where):  # apart from a Bandai run's
        return where / f"{model}{data.data_tag(str(folder))}_0"

    def train(where, iterations, processes=1):
        launch = [sys.executable, "-m", "torch.distributed.run", "--standalone", "--nproc_per_node",
                  str(processes)] if processes > 1 else [sys.executable]
        out = subprocess.run([*launch, str(script), model, str(folder), str(where), str(iterations)],
                             check=False, capture_output=True, text=True, env=env, timeout=300)
        assert out.returncode == 0, out.stderr[-12000:]
        log = (run_folder(where) / "losses.jsonl").read_text().splitlines()
        return [e for e in map(json.loads, log) if "rec" in e]

    def agree(a, b):
        assert [e["iteration"] for e in a] == [e["iteration"] for e in b]
        for x, y in zip(a, b):
            assert all(abs(x[k] - y[k]) <= 2e-5 for k in x if k != "seconds"), (x, y)

    both, one = train(tmp_path / "two", 6, processes=2), train(tmp_path / "one", 6)
    assert [e["iteration"] for e in both] == list(range(1, 7))
    agree(both, one)
    saved = [torch.load(run_folder(where) / "checkpoint.pt", weights_only=False) for where in
             (tmp_path / "two", tmp_path / "one")]
    for part in parts:
        for key, value in saved[0][part].items():
            torch.testing.assert_close(value, saved[1][part][key], atol=1e-3, rtol=0)

    resumed, continued = train(tmp_path / "two", 8), train(tmp_path / "one", 8)
    assert [e["iteration"] for e in resumed] == list(range(1, 9))
    agree(resumed, continued)
    assert (tmp_path / "two" / "models" / exported).is_file()
    assert not (tmp_path / "two" / f"{model}_0").exists()  # a Bandai run's checkpoint folder


_JUDGE = """
import json
import sys
from pathlib import Path

from motion_style_ros.training import judges

folder, where, epochs = sys.argv[1:]
cfg = judges.Config(kind="style", data=folder, epochs=int(epochs), crops_per_epoch=64, batch=16, dropout=0.0)
card = judges.train(cfg, Path(where), checkpoints=Path(where), threads=1, progress=False, device="cpu")
if card is not None:
    Path(where, "history.json").write_text(json.dumps(card["training"]["history"]))
"""


def test_torchrun_trains_a_judge_as_one_process_does(folder, tmp_path, env, torch):
    """2 processes of 8 crops against 1 of 16 (no dropout: its masks are drawn per process), 2
    epochs: the same train and val losses (1e-5), one export; the checkpoint continued in one process."""
    script = tmp_path / "judge.py"
    script.write_text(textwrap.dedent(_JUDGE))
    env = {**env, "OMP_NUM_THREADS": "1"}

    def train(where, epochs, processes=1, printed=2):
        launch = [sys.executable, "-m", "torch.distributed.run", "--standalone", "--nproc_per_node",
                  str(processes)] if processes > 1 else [sys.executable]
        out = subprocess.run([*launch, str(script), str(folder), str(where), str(epochs)], check=False,
                             capture_output=True, text=True, env=env, timeout=300)
        assert out.returncode == 0, out.stderr[-12000:]
        assert out.stdout.count("style epoch") == printed  # by rank 0 only
        return json.loads((where / "history.json").read_text())

    both, one = train(tmp_path / "two", 2, processes=2), train(tmp_path / "one", 2)
    assert len(both) == len(one) == 2
    for a, b in zip(both, one):
        assert abs(a["train_loss"] - b["train_loss"]) < 1e-5 and abs(a["val_loss"] - b["val_loss"]) < 1e-5
    assert [e["epoch"] for e in train(tmp_path / "two", 3, printed=1)] == [1, 2, 3]  # resumed after epoch 2
