"""The backend registry: every backend the node, the CLI and the offline path know is one entry,
with a shipped model and a session class of the real interface."""

import json

import numpy as np
import pytest

from motion_style_ros.errors import MotionStyleError
from motion_style_ros.runtime.backends import BACKENDS, Backend, backend, with_feature
from motion_style_ros.runtime.defaults import StreamSettings
from motion_style_ros.runtime.onnx_model import model_path, read_card
from motion_style_ros.runtime.model_step import Stylized
from motion_style_ros.runtime.stream import StreamSession
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


class EchoStep:
    """A model step of the test's own backend: every model frame's own pose back."""

    delay_frames = 0
    styles = ["echo"]

    def start(self, performers: int, blend_seconds: float) -> None:
        pass

    def restart(self) -> None:
        pass

    def __call__(self, frame, style):
        return Stylized(frame.features[:, :130], frame.features, frame.ankles, frame.lift)


class EchoSession(StreamSession):
    """The whole runtime module of a new frame-by-frame backend: its session around its step."""

    def __init__(self, model, performers: int = 1, input_fps: float | None = None, threads: int = 1,
                 settings: StreamSettings | None = None, **stream) -> None:
        card = read_card(model_path(str(model)))
        super().__init__(card, EchoStep(), performers, input_fps, StreamSettings.of(settings, stream))


@pytest.fixture
def echo(monkeypatch, tmp_path):
    """A backend added as a user would: one registry entry, one session module, one model and card."""
    model = tmp_path / "echo.onnx"
    model.write_bytes(b"")  # the step runs no network
    model.with_suffix(".json").write_text(json.dumps({"kind": "echo", "styles": ["echo"], "fps": 30.0,
                                                      "neutral_style": "echo"}))
    monkeypatch.setitem(BACKENDS, "echo", Backend("echo", "gives the performer back", str(model),
                                                  "test_backends:EchoSession"))
    return model


def test_a_new_backend_is_one_registry_entry_and_its_session(echo, tmp_path, capsys):
    """Nothing in nodes/, cli/ or evaluation/ names a backend: the offline path, the node's
    settings and sessions, and the CLI take the new one from the registry."""
    from motion_style_ros.cli.main import main
    from motion_style_ros.core.synthetic import synthetic_motion
    from motion_style_ros.io import bvh
    from motion_style_ros.runtime import stylizer_settings
    from motion_style_ros.runtime.offline import stylizer

    walk = synthetic_motion("walk", 30.0, 2.0)
    out = stylizer("echo")(walk, "echo")
    assert out.n_frames == walk.n_frames and np.isfinite(out.rotations).all()
    values = {p.name: p.default for p in stylizer_settings.PARAMETERS} | {"backend": "echo", "threads": 1}
    spec = stylizer_settings.check_start(values)
    sessions = stylizer_settings.sessions(spec, str(echo), 2, values)
    assert [type(s).__name__ for s in sessions] == ["EchoSession", "EchoSession"]
    clip = tmp_path / "walk.bvh"
    bvh.write(clip, bvh.BvhClip.from_motion(walk, scale=100.0))
    assert main(["stylize", str(clip), "-o", str(tmp_path / "out.bvh"), "--backend", "echo",
                 "--style", "echo"]) == 0
    assert "style echo" in capsys.readouterr().out and (tmp_path / "out.bvh").is_file()


def test_a_new_backends_trainer_package_brings_its_train_subcommand(echo, monkeypatch, capsys):
    """A trainer package with a ``command`` module (its flags and run) is all ``motion-style train``
    needs: nothing in cli/ names it."""
    import importlib.machinery
    import sys
    import types

    from motion_style_ros.cli.main import main
    from motion_style_ros.training.command import TrainCommand

    ran = []
    for name, package in (("motion_style_ros.training.echo", True), ("motion_style_ros.training.echo.command", False)):
        module = types.ModuleType(name)
        module.__spec__ = importlib.machinery.ModuleSpec(name, None, is_package=package)
        monkeypatch.setitem(sys.modules, name, module)
    command = sys.modules["motion_style_ros.training.echo.command"]
    command.COMMAND = TrainCommand("the echo stylizer", "Echoes.", 7.0, "echo.onnx", flags=(
        ("--loudness", dict(type=float, default=1.0, help="how loud")),))
    command.run = lambda args: ran.append((args.minutes, args.loudness)) or 0
    assert main(["train", "echo", "--loudness", "2"]) == 0
    assert ran == [(7.0, 2.0)]
    with pytest.raises(SystemExit):
        main(["train", "--help"])
    assert "the echo stylizer" in capsys.readouterr().out
