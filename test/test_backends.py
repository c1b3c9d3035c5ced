"""The backend registry: every backend the node, the CLI and the offline path know is one entry,
with a shipped model and a session class of the real interface."""

import json

import pytest

from motion_style_ros.errors import MotionStyleError
from motion_style_ros.runtime.backends import BACKENDS, backend, with_feature
from motion_style_ros.runtime.onnx_model import model_path, read_card
from motion_style_ros.runtime.windows import WindowsSession


def test_every_backend_has_its_model_and_session():
    for spec in BACKENDS.values():
        card = read_card(model_path(spec.default_model))
        session = spec.session_class()
        assert callable(getattr(session, "step")) and card["styles"]
        # the windowed backends (lookahead, hop) are the sessions of windows, and only they
        assert spec.lookahead == issubclass(session, WindowsSession)
        assert not spec.reference_clips or spec.lookahead
    assert "stgcn" in with_feature("reference_clips") and "recurrent" not in with_feature("reference_clips")


def test_each_shipped_card_is_of_its_backends_kind_and_an_older_stgcn_card_still_reads(tmp_path):
    for name, spec in BACKENDS.items():
        assert read_card(model_path(spec.default_model))["kind"] == name
        assert spec.session.split(":")[0].rsplit(".", 1)[1] == name  # its module is named after it
    old = tmp_path / "old.json"
    old.write_text(json.dumps({**read_card(model_path("stgcn.onnx")), "kind": "windowed"}))
    assert read_card(tmp_path / "old.onnx")["kind"] == "stgcn"


def test_an_unknown_backend_is_one_line_naming_the_others():
    with pytest.raises(MotionStyleError, match=f"unknown backend 'lstm'; allowed: {', '.join(BACKENDS)}$"):
        backend("lstm")
