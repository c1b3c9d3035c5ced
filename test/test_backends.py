"""The backend registry: every backend the node, the CLI and the offline path know is one entry,
with a shipped model and a session class of the real interface."""

import pytest

from motion_style_ros.errors import MotionStyleError
from motion_style_ros.runtime.backends import BACKENDS, backend, with_feature
from motion_style_ros.runtime.offline import STYLIZERS
from motion_style_ros.runtime.onnx_model import model_path, read_card


def test_every_backend_has_its_model_session_and_offline_stylizer():
    assert set(STYLIZERS) == set(BACKENDS)
    for spec in BACKENDS.values():
        card = read_card(model_path(spec.default_model))
        session = spec.session_class()
        assert callable(getattr(session, "step")) and card["styles"]
        assert spec.lookahead == (card["kind"] == "windowed")
    assert with_feature("reference_clips") == ["stgcn"]


def test_an_unknown_backend_is_one_line_naming_the_others():
    with pytest.raises(MotionStyleError, match="unknown backend 'lstm'; allowed: recurrent, stgcn"):
        backend("lstm")
