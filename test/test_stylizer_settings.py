"""runtime/stylizer_settings.py: the stylizer node's parameters without ROS."""

from pathlib import Path

import pytest
import yaml

from motion_style_ros.errors import MotionStyleError
from motion_style_ros.runtime import stylizer_settings as settings
from motion_style_ros.runtime.backends import BACKENDS, with_feature
from motion_style_ros.runtime.defaults import DEFAULTS
from motion_style_ros.runtime.recurrent import RecurrentSession

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_VALUES = {p.name: p.default for p in settings.PARAMETERS}


def test_the_params_file_lists_every_parameter_at_the_tables_default():
    listed = yaml.safe_load((ROOT / "config" / "stylizer.yaml").read_text())["/**/stylizer"]["ros__parameters"]
    qos = {k: listed.pop(k) for k in list(listed) if "qos" in k}
    assert set(qos) == {"qos_reliability", "qos_depth", "trajectory_qos_reliability", "trajectory_qos_depth"}
    assert "target_style" not in listed  # the model's neutral style, from its card
    assert listed == DEFAULT_VALUES


def test_the_sessions_settings_default_to_the_one_source():
    for name in ("hop", "lookahead", "blend_seconds", "foot_lock", "pipelined", "seed_spread"):
        assert DEFAULT_VALUES[name] == DEFAULTS[name], name
    assert DEFAULT_VALUES["follow_seconds"] == (DEFAULTS["follow_seconds"] or 0.0)  # 0: free


def test_start_values_that_do_not_go_together_say_what_is_allowed():
    assert settings.check_start(DEFAULT_VALUES) is BACKENDS["recurrent"]
    for change, expected in [({"backend": "gan"}, f"allowed: {', '.join(BACKENDS)}"),
                             ({"trajectory_velocities": "some"}, "allowed: inner, all, none"),
                             ({"style_bank": "bank.json"}, "needs backend stgcn"),
                             ({"performers": ["a", "a"]}, "distinct topic prefixes"),
                             ({"performers": []}, "distinct topic prefixes")]:
        with pytest.raises(MotionStyleError, match=expected):
            settings.check_start({**DEFAULT_VALUES, **change})


def test_a_live_change_is_checked_for_its_type_style_and_backend():
    styles, recurrent = ["normal", "elderly"], BACKENDS["recurrent"]
    assert settings.problem("alpha", 0.5, styles, recurrent) is None
    assert "must be of type double, got integer 1" in settings.problem("alpha", 1, styles, recurrent)
    assert "this model knows: normal, elderly" in settings.problem("target_style", "proud", styles, recurrent)
    assert settings.problem("mix_style", "", styles, recurrent) is None
    assert "needs backend stgcn or most or saae (its style encoder)" in settings.problem(
        "reference", "walk.bvh", styles, recurrent)
    for name in ("stgcn", "most", "saae"):
        assert settings.problem("reference", "walk.bvh", styles, BACKENDS[name]) is None
        assert settings.problem("latent_seed", 7, styles, BACKENDS[name]) is None  # (ignored without seeds)


def test_a_backend_specific_parameter_names_the_backends_it_is_for():
    described = {p.name: p.description for p in settings.PARAMETERS}
    for name, feature in [("window", "lookahead"), ("hop", "lookahead"), ("lookahead", "lookahead"),
                          ("style_bank", "style_bank"), ("latent_seed", "latent_seeds"),
                          ("seed_spread", "latent_seeds"), ("reference", "reference_clips")]:
        assert described[name].startswith(f"{', '.join(with_feature(feature))}: "), (name, described[name])
    assert described["reference"].startswith("stgcn, most, saae: a BVH clip")
    assert "recurrent, most, saae have no latent seeds and ignore it" in described["latent_seed"]
    assert described["backend"] == f"stylizer backend: {', '.join(BACKENDS)}"


def test_recurrent_sessions_run_their_model_frames_on_different_input_frames():
    values = {**DEFAULT_VALUES, "input_fps": 120.0}
    made = settings.sessions(BACKENDS["recurrent"], "style_erd.onnx", 5, values)
    assert all(isinstance(s, RecurrentSession) for s in made)
    # at 120 Hz one input frame in four runs the model: four phases, then round again
    assert [round(s._phase * 120) for s in made] == [0, 1, 2, 3, 0]
    assert made[0].gap_seconds == DEFAULTS["gap_seconds"] and made[0].latency == pytest.approx(0.025)


def test_apply_hands_each_change_to_every_session():
    from motion_style_ros.core.synthetic import synthetic_motion

    walk = synthetic_motion("walk", 30.0, 1.0)
    made = settings.sessions(BACKENDS["recurrent"], "style_erd.onnx", 2, DEFAULT_VALUES)
    current = {k: DEFAULT_VALUES.get(k, "normal") for k in settings.DYNAMIC}
    settings.apply(made, BACKENDS["recurrent"], current, current, None)  # the node's start: every value
    settings.apply(made, BACKENDS["recurrent"], current, {"target_style": "elderly", "alpha": 0.25}, None)
    by_hand = settings.sessions(BACKENDS["recurrent"], "style_erd.onnx", 1, DEFAULT_VALUES)[0]
    by_hand.set_style("elderly")
    by_hand.set_alpha(0.25)
    untouched = settings.sessions(BACKENDS["recurrent"], "style_erd.onnx", 1, DEFAULT_VALUES)[0]
    for t in range(walk.n_frames):
        frame = walk.rotations[t], walk.root_positions[t], t / 30.0
        want, other = by_hand.step(*frame), untouched.step(*frame)
        for s in made:
            got = s.step(*frame)
            assert all((g == w).all() for g, w in zip(got, want))
    assert abs(want[0] - other[0]).max() > 1e-3  # the change made a difference


def test_windowed_sessions_run_their_windows_on_different_input_frames():
    values = {**DEFAULT_VALUES, "input_fps": 120.0}
    made = settings.sessions(BACKENDS["stgcn"], "stgcn.onnx", 3, values)
    assert [type(s).__name__ for s in made] == ["StgcnSession"] * 3
    assert [round(s._phase * 120) for s in made] == [0, 1, 2]
    assert all(s.lookahead == DEFAULTS["lookahead"] for s in made)
