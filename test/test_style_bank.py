"""The style bank: a style enrolled from clips becomes a target the windowed session and the CLI
take, kept in a file that only its own model accepts; bad banks and names are one-line errors."""

import json
import shutil
import subprocess
import sys

import numpy as np
import pytest
from onnx_fixtures import windowed_model

from motion_style_ros.core.synthetic import synthetic_motion
from motion_style_ros.errors import MotionStyleError
from motion_style_ros.io import bvh
from motion_style_ros.io.datasets import ClipInfo, load_clip
from motion_style_ros.runtime import style_bank
from motion_style_ros.runtime.stgcn import StgcnSession

STYLES = ["active", "elderly", "normal", "youthful"]
BANDAI = "bandai-namco/Bandai-Namco-Research-Motiondataset-2/data"
TAKES = ["dataset-2_walk_youthful_001", "dataset-2_run_youthful_001", "dataset-2_wave-left-hand_youthful_001"]


@pytest.fixture(scope="module")
def model(tmp_path_factory):
    return windowed_model(tmp_path_factory.mktemp("bank") / "stgcn.onnx", STYLES)


@pytest.fixture(scope="module")
def clips(datasets):
    return [load_clip(ClipInfo("bandai-2", datasets / BANDAI / f"{n}.bvh", n, "", "", "", "")) for n in TAKES]


def test_an_enrolled_style_is_a_target_with_its_own_code(model, clips, tmp_path):
    session = StgcnSession(model, window=16, lookahead=8)
    entry = session.enrol(clips, TAKES)
    assert entry.head in STYLES and entry.frames == sum(m.n_frames for m in clips)  # Bandai is 30 fps
    codes = [session.reference_codes(m)[0][STYLES.index(entry.head)] for m in clips]
    expected = np.average(codes, axis=0, weights=[m.n_frames for m in clips])
    np.testing.assert_allclose(entry.code, expected, atol=1e-6)
    bank = tmp_path / "bank.json"
    style_bank.write(bank, {"bouncy": entry}, "stgcn", session.model_digest)

    enrolled = StgcnSession(model, window=16, lookahead=8, bank=bank)
    assert enrolled.styles == STYLES + ["bouncy"]
    np.testing.assert_allclose(enrolled.codes()[-1], entry.code, atol=1e-6)
    enrolled.set_seed(7)  # seeds move the model's styles, never an enrolled one
    np.testing.assert_allclose(enrolled.codes()[-1], entry.code, atol=1e-6)
    walk = clips[0]
    out = enrolled.run(walk, "bouncy")
    normal = enrolled.run(walk, "normal")
    assert np.isfinite(out.positions).all()
    assert np.abs(out.positions - normal.positions).max() > 1e-3  # the enrolled code is the one used
    # a reference read for an enrolled style goes under that style's head
    assert enrolled.set_reference(clips[1], style="bouncy") == "bouncy"


def test_the_bank_beside_the_model_is_read_by_default_and_refused_by_another_model(model, clips, tmp_path):
    session = StgcnSession(model, window=16, lookahead=8)
    entry = session.enrol(clips[:1], TAKES[:1], head="elderly")
    assert entry.head == "elderly"
    here = tmp_path / "stgcn.onnx"
    for f in model.parent.glob("stgcn*"):
        shutil.copy(f, tmp_path / f.name)
    style_bank.write(style_bank.path_beside(here), {"mine": entry}, "stgcn", session.model_digest)
    assert StgcnSession(here, window=16, lookahead=8).styles[-1] == "mine"
    from motion_style_ros.cli.eval import _styles_offered  # eval asks the bank's styles too

    assert _styles_offered(here) == [*STYLES, "mine"] and _styles_offered(model) == STYLES
    other = tmp_path / "other.json"
    style_bank.write(other, {"mine": entry}, "stgcn", "0" * 16)
    with pytest.raises(MotionStyleError, match="made for another model"):
        StgcnSession(model, lookahead=8, bank=other)


@pytest.mark.parametrize("content, reason", [
    ("not json", "not a style bank"),
    ('{"version": 9, "styles": {}}', "not a version-1 style bank"),
    (None, "no finite 4-value code"),
])
def test_bad_banks_are_one_line_errors(model, tmp_path, content, reason):
    session = StgcnSession(model, window=16, lookahead=8)
    bank = tmp_path / "bank.json"
    if content is None:  # a valid file whose code has the wrong size
        entry = style_bank.Entry((0.0,) * 4, "normal", ("a.bvh",), 10, {"normal": 1.0})
        style_bank.write(bank, {"mine": entry}, "stgcn", session.model_digest)
        raw = json.loads(bank.read_text())
        raw["styles"]["mine"]["code"] = [1.0, 2.0]
        bank.write_text(json.dumps(raw))
    else:
        bank.write_text(content)
    with pytest.raises(MotionStyleError, match=reason):
        style_bank.read(bank, session.model_digest, 4 if content is None else 8, STYLES)


@pytest.mark.parametrize("name, reason", [("Proud", "lowercase"), ("", "lowercase"), ("normal", "knows already")])
def test_style_names_must_be_new_and_plain(name, reason):
    with pytest.raises(MotionStyleError, match=reason):
        style_bank.check_name(name, STYLES)


def test_the_cli_adds_lists_and_removes_styles(model, datasets, tmp_path):
    bank = tmp_path / "mine.json"
    files = [str(datasets / BANDAI / f"{n}.bvh") for n in TAKES]

    def cli(*args):
        return subprocess.run([sys.executable, "-m", "motion_style_ros.cli.main", "style", *args,
                               "--model", str(model), "--bank", str(bank)], capture_output=True, text=True)

    added = cli("add", "bouncy", *files)
    assert added.returncode == 0, added.stderr
    assert "bouncy: 3 clips" in added.stdout and "1 enrolled styles" in added.stdout
    again = cli("add", "bouncy", files[0])
    assert again.returncode == 2 and "--replace" in again.stderr and "Traceback" not in again.stderr
    assert "bouncy: 3 clips" in cli("list").stdout
    assert StgcnSession(model, lookahead=8, bank=bank).styles[-1] == "bouncy"
    short = tmp_path / "short.bvh"
    bvh.write(short, bvh.BvhClip.from_motion(synthetic_motion("walk", 30.0, 0.3), scale=100.0))
    with_short = cli("add", "brisk", files[0], str(short))
    assert with_short.returncode == 0, with_short.stderr
    assert "brisk: 1 clips" in with_short.stdout
    assert "left out short.bvh: reference clip too short" in with_short.stderr
    only_short = cli("add", "other", str(short))
    assert only_short.returncode == 2 and "none of the 1 clips can serve: short.bvh" in only_short.stderr
    assert cli("remove", "brisk").returncode == 0
    missing = cli("add", "other", str(tmp_path / "nope.bvh"))
    assert missing.returncode == 2 and "nope.bvh" in missing.stderr
    assert cli("remove", "bouncy").returncode == 0
    assert "no enrolled styles" in cli("list").stdout


def test_a_mixed_entry_weighs_every_heads_code_by_the_classifiers_probabilities(model, clips):
    session = StgcnSession(model, window=16, lookahead=8)
    entry = session.enrol(clips, TAKES, head=style_bank.MIX)
    read = [session.reference_codes(m) for m in clips]
    per_clip = []
    for codes, logits in read:
        p = np.exp(logits - logits.max())
        per_clip.append((p / p.sum()) @ codes)
    expected = np.average(per_clip, axis=0, weights=[m.n_frames for m in clips])
    assert entry.head == "mix"
    np.testing.assert_allclose(entry.code, expected, atol=1e-6)
