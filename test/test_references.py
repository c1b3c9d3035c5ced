"""runtime/references.py: reference clips read off the streams' thread (the shipped ST-GCN model's
style encoder, a real Bandai clip)."""

import threading
from collections import deque
from pathlib import Path

import numpy as np
import pytest
from bad_files import unretargetable_clip

from motion_style_ros.errors import MotionStyleError
from motion_style_ros.io.canonical import canonical_clip
from motion_style_ros.runtime.backends import BACKENDS
from motion_style_ros.runtime.references import REVERT, References


@pytest.fixture(scope="module")
def session():
    return BACKENDS["stgcn"].session_class()(BACKENDS["stgcn"].default_model)


@pytest.fixture
def clip(datasets):
    return str(datasets / "bandai-namco" / "Bandai-Namco-Research-Motiondataset-2" / "data"
               / "dataset-2_walk_elderly_001.bvh")


def make(session):
    errors = []
    return References(session, deque(), errors.append), errors


def test_a_clip_is_read_on_a_worker_and_its_change_queued_with_its_codes(session, clip):
    refs, errors = make(session)
    refs.check(clip)
    changes = {"reference": clip, "target_style": "elderly"}
    refs.load(clip, "", changes).join(60)
    assert list(refs.pending) == [changes] and not errors
    codes, logits = refs.staged[clip]
    np.testing.assert_array_equal(codes, session.reference_codes(canonical_clip(clip))[0])
    assert session.styles[int(np.argmax(logits))] == "elderly"


def test_what_the_header_tells_is_refused_at_once_with_a_reason(session, clip, tmp_path):
    refs, _ = make(session)
    lines = open(clip).read().splitlines()
    short = tmp_path / "short.bvh"
    frames_at = next(i for i, line in enumerate(lines) if line.startswith("Frames:"))
    short.write_text("\n".join(lines[:frames_at] + ["Frames: 10", lines[frames_at + 1]] +
                               lines[frames_at + 2:frames_at + 12]) + "\n")
    with pytest.raises(MotionStyleError, match="reference clip too short"):
        refs.check(str(short))
    (tmp_path / "notes.bvh").write_text("not a motion\n")
    for bad in (tmp_path / "missing.bvh", tmp_path / "notes.bvh"):
        with pytest.raises(MotionStyleError):
            refs.check(str(bad))


def test_a_clip_that_cannot_be_used_queues_a_revert_and_says_why(session, clip, tmp_path):
    refs, errors = make(session)
    garbled = tmp_path / "garbled.bvh"
    text = open(clip).read()
    garbled.write_text(text[: len(text) // 2] + "\nnot numbers at all\n")
    with pytest.raises(MotionStyleError, match="non-number"):
        refs.check(str(garbled))  # found at once, in the set callback
    broken = Path(unretargetable_clip(tmp_path))
    refs.check(str(broken))  # a well-formed BVH: only the worker finds it is no humanoid
    refs.load(str(broken), clip, {"reference": str(broken)}).join(60)
    assert list(refs.pending) == [{REVERT: clip}]
    assert len(errors) == 1 and "parameter reference:" in errors[0] and "keeping" in errors[0]
    assert "not a humanoid skeleton" in refs.failure  # for /diagnostics, until a clip is taken
    # without a clip before it, the log says what '' means: the node's wording for its backend
    errors = []
    refs = References(session, deque(), errors.append, "the styles' own inputs")
    refs.load(str(broken), "", {"reference": str(broken)}).join(60)
    assert list(refs.pending) == [{REVERT: ""}]
    assert len(errors) == 1 and errors[0].endswith("keeping \"the styles' own inputs\""), errors


def test_only_the_newest_clip_asked_for_is_applied(session, clip):
    refs, _ = make(session)
    first_may_finish = threading.Event()
    read = refs.read
    refs.read = lambda path: (first_may_finish.wait(60) if path == "first" else True) and read(clip)
    first = refs.load("first", "", {"reference": "first"})
    refs.load(clip, "", {"reference": clip}).join(60)
    first_may_finish.set()
    first.join(60)
    assert list(refs.pending) == [{"reference": clip}]
