"""Dataset indexers, the committed Bandai split, the preprocessing cache and bad-file handling.

Index and split tests read the real datasets; cache and bad-file tests run on a few real files copied
into a temporary tree (with the cache in a temporary folder), so they never build the full cache.
"""

import csv
import json
import logging
import os
import shutil
import subprocess
import sys
from collections import Counter, defaultdict

import numpy as np
import pytest

from motion_style_ros.core import rotations as rot
from motion_style_ros.core.skeleton import canonical, cmu31
from motion_style_ros.errors import MotionStyleError
from motion_style_ros.io import bvh, cache
from motion_style_ros.io import datasets as ds
from motion_style_ros.io.canonical import BONE_TOLERANCE

D2 = "Bandai-Namco-Research-Motiondataset-2"
SMALL = [f"dataset-2_raise-up-both-hands_active_{t}" for t in ("013", "014", "022", "025")]
SMALL.append("dataset-2_wave-left-hand_active_011")
D2_STYLES = {"active", "elderly", "exhausted", "feminine", "masculine", "normal", "youthful"}
D2_CONTENTS = {
    "walk", "walk-turn-left", "walk-turn-right", "run", "wave-both-hands", "wave-left-hand",
    "wave-right-hand", "raise-up-both-hands", "raise-up-left-hand", "raise-up-right-hand",
}


@pytest.fixture(scope="module")
def bandai(datasets):
    return ds.index_bandai(datasets)


def copy_bandai(datasets, dest, names):
    """A dataset tree under ``dest`` holding only ``names`` of dataset-2 (BVH, JSON and cfg/)."""
    src = datasets / "bandai-namco" / D2
    out = dest / "bandai-namco" / D2
    shutil.copytree(src / "cfg", out / "cfg")
    (out / "data").mkdir()
    for name in names:
        for ext in (".bvh", ".json"):
            shutil.copy2(src / "data" / (name + ext), out / "data" / (name + ext))
    return dest


# --- indexers on the real data ------------------------------------------------------------------


def test_bandai_index_counts(bandai):
    by_set = defaultdict(list)
    for info in bandai:
        by_set[info.dataset].append(info)
    assert {k: len(v) for k, v in by_set.items()} == {"bandai-1": 174, "bandai-2": 2902}
    assert {i.style for i in by_set["bandai-2"]} == D2_STYLES
    assert {i.content for i in by_set["bandai-2"]} == D2_CONTENTS
    assert len({i.style for i in by_set["bandai-1"]}) == 15
    # Dataset-1 styles never merge into dataset-2's: the names both sets use get a suffix.
    assert {i.style for i in by_set["bandai-1"]} & D2_STYLES == set()
    assert {"active-d1", "feminine-d1", "normal-d1", "proud", "tired"} <= {i.style for i in by_set["bandai-1"]}
    assert all(i.name.split("_")[2] == i.style.removesuffix("-d1") for i in bandai)
    assert len({i.name for i in bandai}) == len(bandai)
    assert all(i.path.is_file() and i.path.stem == i.name for i in bandai)


def test_real_bandai_data_indexes_without_warnings(datasets, caplog):
    with caplog.at_level(logging.WARNING):
        ds.index_bandai(datasets)
    assert not caplog.records


def test_bandai_labels_agree_with_json_and_labels_csv(bandai, datasets):
    listed = {}
    with open(datasets / "bandai-namco" / "labels.csv", newline="") as f:
        for row in csv.DictReader(f):
            listed[row["file"].rsplit("/", 1)[-1][:-4]] = (row["content"], row["style"], row["take"])
    cfg = {}
    for info in bandai:
        base = info.path.parent.parent
        if base not in cfg:
            cfg[base] = [[w.split("_", 1)[1] for w in (base / "cfg" / f).read_text().split()]
                         for f in ("content_label.txt", "style_label.txt")]
        label = json.loads(info.path.with_suffix(".json").read_text())
        contents, styles = cfg[base]
        style = ds.style_label(info.dataset, styles[label["style"]])
        assert (contents[label["content"]], style) == (info.content, info.style)
        content, named, take = listed.pop(info.name)
        assert (content, ds.style_label(info.dataset, named), take) == (info.content, info.style, info.take)
    assert not listed  # labels.csv lists no clip the index missed


def test_split_file_covers_every_clip_and_follows_the_rule(bandai, datasets):
    committed = ds.split_file().read_text()
    rows = list(csv.DictReader(committed.splitlines()))
    assert [r["name"] for r in rows] == sorted(r["name"] for r in rows)
    assert {r["name"] for r in rows} == {i.name for i in bandai}
    assert set(r["split"] for r in rows) == {"train", "val", "test"}
    assert {r["name"]: r["split"] for r in rows} == {i.name: i.split for i in bandai}
    assert ds.split_csv(datasets) == committed  # what `motion-style data split --write` writes


def test_split_by_take_with_every_cell_in_train_and_test(bandai):
    takes = Counter((i.dataset, i.content, i.style, i.take) for i in bandai)
    assert max(takes.values()) == 1  # one file per take, so a take cannot straddle two splits
    cells = defaultdict(Counter)
    for i in bandai:
        if i.dataset == "bandai-2":
            cells[i.content, i.style][i.split] += 1
    assert len(cells) == 70
    assert all(c["train"] and c["val"] and c["test"] for c in cells.values())
    total = Counter(i.split for i in bandai if i.dataset == "bandai-2")
    assert 0.13 < total["test"] / 2902 < 0.18
    assert 0.08 < total["val"] / 2902 < 0.12
    d1 = [i for i in bandai if i.dataset == "bandai-1"]
    assert {i.name for i in d1 if i.split == "test"} == {i.name for i in d1 if i.take != "001"}
    assert {i.style for i in d1 if i.split == "test" and i.content == "walk"} == {i.style for i in d1}
    assert {i.split for i in d1} == {"train", "test"}


def test_cmu_and_xia_index(datasets):
    cmu = ds.index_cmu(datasets)
    assert len(cmu) == len(list((datasets / "cmu" / "data").glob("*/*.bvh"))) == 22
    with open(datasets / "cmu" / "labels.csv", newline="") as f:
        categories = {r["file"].rsplit("/", 1)[-1][:-4]: r["category"] for r in csv.DictReader(f)}
    assert {i.name: i.content for i in cmu} == categories
    assert {(i.style, i.split) for i in cmu} == {("neutral", "unseen")}
    assert next(i for i in cmu if i.name == "07_12").take == "12"
    xia = ds.index_xia(datasets)
    assert len(xia) == len(list((datasets / "xia-test").glob("*.bvh"))) == 9
    assert {i.split for i in xia} == {"unseen"}
    by_name = {i.name: (i.style, i.content, i.take) for i in xia}
    assert by_name["sexy_01_001"] == ("sexy", "walk", "001")
    assert by_name["depressed_18_000"] == ("depressed", "punch", "000")
    assert by_name["neutral_16_000"][1] == "jump"
    assert ds.load_clip(xia[0]).skeleton.names == cmu31().names


def test_load_clip_keeps_the_trajectory_that_joint_root_carries(bandai):
    # An in-place cycle whose forward motion is on joint_Root: the clip must still travel.
    info = next(i for i in bandai if i.name == "dataset-1_dash_normal_001")
    motion = ds.load_clip(info)
    assert motion.skeleton.names == canonical().names and motion.fps == 30.0
    assert np.allclose(motion.rotations[:, 0], rot.identity())
    assert np.allclose(motion.positions[:, 0], 0.0)
    raw = bvh.read(info.path).to_motion(scale=0.01)
    assert np.ptp(raw.positions[:, 0, 2]) > 2.0  # the file moves joint_Root ...
    assert np.ptp(motion.root_positions[:, 2]) > 2.0  # ... and the loaded Hips follow it
    # The body moves exactly as in the file, up to the recording's sub-millimetre bone differences.
    body = np.s_[:, 1:]
    assert np.abs(motion.global_positions()[body] - raw.global_positions()[body]).max() < BONE_TOLERANCE


def test_missing_datasets_name_the_unpack_script(tmp_path, monkeypatch):
    monkeypatch.setenv("MOTION_STYLE_DATASETS", str(tmp_path / "nowhere"))
    with pytest.raises(MotionStyleError, match="unpack.sh"):
        ds.datasets_root()


# --- cache on a small temporary copy ------------------------------------------------------------


def test_cache_equals_fresh_parse_and_rebuilds_when_a_file_changes(datasets, tmp_path, monkeypatch):
    root = copy_bandai(datasets, tmp_path / "data", SMALL)
    monkeypatch.setenv("MOTION_STYLE_CACHE", str(tmp_path / "cache"))
    infos = ds.index_bandai(root, (2,))
    assert [i.name for i in infos] == sorted(SMALL)

    first = ds.load_bandai(infos, progress=False)
    entry = cache.entry_path(f"bandai-2.v{ds.CACHE_VERSION}")
    built = entry.stat().st_mtime_ns
    assert [i for i, _ in first] == infos
    for info, motion in first:
        fresh = ds.load_clip(info)
        assert motion.rotations.dtype == np.float32 and motion.n_frames == fresh.n_frames
        assert np.abs(motion.rotations - fresh.rotations).max() < 1e-6
        assert np.abs(motion.root_positions - fresh.root_positions).max() < 1e-5

    again = ds.load_bandai(infos[:2], progress=False)
    assert entry.stat().st_mtime_ns == built  # served from the cache, not rebuilt
    assert [i for i, _ in again] == infos[:2]
    assert np.array_equal(again[1][1].rotations, first[1][1].rotations)

    # Raise the Hips by 10 cm in one file: the cache must notice and serve the new numbers.
    changed = infos[1]
    clip = bvh.read(changed.path)
    clip.data[:, 7] += 10.0  # Hips Yposition (after joint_Root's 6 channels), cm
    bvh.write(changed.path, clip)
    after = dict(ds.load_bandai(infos, progress=False))
    assert entry.stat().st_mtime_ns != built
    lift = after[changed].root_positions[:, 1] - dict(first)[changed].root_positions[:, 1]
    assert np.allclose(lift, 0.1, atol=1e-5)


def test_clip_missing_from_the_split_file_fails_loudly(datasets, tmp_path):
    root = copy_bandai(datasets, tmp_path, SMALL[:1])
    data = root / "bandai-namco" / D2 / "data"
    for ext in (".bvh", ".json"):
        shutil.copy(data / (SMALL[0] + ext), data / ("dataset-2_raise-up-both-hands_active_999" + ext))
    with pytest.raises(MotionStyleError, match="active_999.*split --write"):
        ds.index_bandai(root, (2,))


# --- bad files ----------------------------------------------------------------------------------

BAD = {  # name -> words the warning must contain
    "dataset-2_raise-up-both-hands_active_015": "truncated",
    "dataset-2_raise-up-both-hands_active_016": "0 frames",
    "dataset-2_raise-up-both-hands_active_017": "non-number 'nan'",
    "dataset-2_raise-up-both-hands_active_018": "says run/active but the file name says raise-up",
    "dataset-2_raise-up-both-hands_active_019": "'Head2' where 'Head' was expected",
    "dataset-2_raise-up-both-hands_active_021": "no dataset-2_raise-up-both-hands_active_021.json",
}
WRONG_BONES = "dataset-2_raise-up-both-hands_active_023"  # passes indexing, fails loading


def nan_in_last_frame(text):
    frames, last = text.rstrip("\n").rsplit("\n", 1)
    values = last.split()
    values[3] = "nan"
    return f"{frames}\n{' '.join(values)}\n"


@pytest.fixture
def bad_root(datasets, tmp_path):
    root = copy_bandai(datasets, tmp_path / "data", SMALL[:2] + list(BAD) + [WRONG_BONES])
    data = root / "bandai-namco" / D2 / "data"
    names = iter(BAD)

    def edit(transform):
        path = data / (next(names) + ".bvh")
        path.write_text(transform(path.read_text()))

    edit(lambda text: text[: int(len(text) * 0.7)])
    edit(lambda text: text[: text.index("Frames:")] + "Frames: 0\nFrame Time: 0.0333333\n")
    edit(nan_in_last_frame)
    (data / (next(names) + ".json")).write_text('{"content": 3, "style": 0}')
    edit(lambda text: text.replace("JOINT Head\n", "JOINT Head2\n"))
    (data / (next(names) + ".json")).unlink()
    clip = bvh.read(data / (WRONG_BONES + ".bvh"))
    clip.data[:, 15 * 6] += 5.0  # LowerLeg_L Xposition: a thigh 5 cm longer, another skeleton
    bvh.write(data / (WRONG_BONES + ".bvh"), clip)
    return root


def test_bad_files_warn_once_each_and_are_skipped(bad_root, tmp_path, monkeypatch, caplog):
    monkeypatch.setenv("MOTION_STYLE_CACHE", str(tmp_path / "cache"))
    with caplog.at_level(logging.WARNING):
        infos = ds.index_bandai(bad_root, (2,))
    assert [i.name for i in infos] == sorted(SMALL[:2] + [WRONG_BONES])
    messages = [r.getMessage() for r in caplog.records]
    assert len(messages) == len(BAD)
    for name, words in BAD.items():
        (line,) = [m for m in messages if f"{name}.bvh: " in m]
        assert words in line and line.endswith("; skipped") and "\n" not in line

    for attempt in ("build", "cached"):
        caplog.clear()
        with caplog.at_level(logging.WARNING):
            loaded = ds.load_bandai(infos, progress=False)
        assert [i.name for i, _ in loaded] == sorted(SMALL[:2]), attempt
        (line,) = [r.getMessage() for r in caplog.records if WRONG_BONES in r.getMessage()]
        assert "LowerLeg_L is 5.0 cm from the canonical skeleton" in line, attempt


def test_cli_index_reports_bad_files_without_traceback(bad_root, tmp_path):
    env = dict(os.environ, MOTION_STYLE_DATASETS=str(bad_root), MOTION_STYLE_CACHE=str(tmp_path / "c"))
    out = subprocess.run(
        [sys.executable, "-m", "motion_style_ros.cli.main", "data", "index", "--dataset", "bandai-2"],
        capture_output=True, text=True, env=env, timeout=120,
    )
    assert out.returncode == 0, out.stderr
    assert "Traceback" not in out.stderr
    warnings = out.stderr.strip().splitlines()
    assert len(warnings) == len(BAD)
    assert all(any(f"{name}.bvh: " in w for w in warnings) for name in BAD)
    assert "bandai-2: 3 clips" in out.stdout


def test_cli_split_check_passes_on_the_real_data(datasets):
    env = dict(os.environ, MOTION_STYLE_DATASETS=str(datasets))
    out = subprocess.run(
        [sys.executable, "-m", "motion_style_ros.cli.main", "data", "split", "--check"],
        capture_output=True, text=True, env=env, timeout=120,
    )
    assert out.returncode == 0, out.stdout + out.stderr
    assert "3076 clips" in out.stdout
