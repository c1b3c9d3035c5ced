"""Training data: mirrored copies of train takes (left and right contents swapped), styles left out,
speed copies; a style that cannot be left out is a one-line error."""

import numpy as np
import pytest

pytest.importorskip("torch", reason="the trainers' data needs torch: pip install '.[train]'")

from motion_style_ros.core.features import encode
from motion_style_ros.core.mirror import mirror
from motion_style_ros.errors import MotionStyleError
from motion_style_ros.io.datasets import index_bandai, load_bandai
from motion_style_ros.training import data


@pytest.fixture(scope="module")
def plain(datasets):
    return data.load_data((2,), progress=False, root=datasets, takes_per_cell=1)


@pytest.fixture(scope="module")
def augmented(datasets):
    return data.load_data((2,), progress=False, root=datasets, takes_per_cell=1, speeds=(0.8,), mirror=True,
                          exclude=("elderly",))


def test_mirrored_and_speed_copies_join_the_train_takes_only(plain, augmented):
    train, val = plain.splits["train"], augmented.splits["val"]
    kept = np.flatnonzero(train.styles != plain.styles.index("elderly"))
    # each kept take: itself, at 0.8, mirrored, mirrored at 0.8
    assert len(augmented.splits["train"].features) == 4 * len(kept)
    assert len(val.features) == np.sum(plain.splits["val"].styles != plain.styles.index("elderly"))
    assert "elderly" not in augmented.styles and augmented.contents == plain.contents


def test_a_mirrored_take_has_the_other_side_content_and_the_mirrored_features(augmented, datasets):
    info = next(i for i in index_bandai(datasets, datasets=(2,))
                if i.split == "train" and i.content == "raise-up-left-hand" and i.style == "active")
    (_, motion), = load_bandai([info], progress=False)
    want = encode(mirror(motion))
    clips = augmented.splits["train"]
    match = [k for k, f in enumerate(clips.features) if f.shape == want.shape and np.allclose(f, want, atol=1e-5)]
    assert len(match) == 1
    assert augmented.contents[clips.contents[match[0]]] == "raise-up-right-hand"


def test_leaving_out_an_unknown_or_the_neutral_style_is_refused(datasets):
    with pytest.raises(MotionStyleError, match="cannot leave out proud: the styles to leave out are among active"):
        data.load_data((2,), progress=False, root=datasets, takes_per_cell=1, exclude=("proud",))
    with pytest.raises(MotionStyleError, match="cannot leave out normal"):
        data.load_data((2,), progress=False, root=datasets, takes_per_cell=1, exclude=("normal",))
