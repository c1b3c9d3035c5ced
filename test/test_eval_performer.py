"""The learned performer's measures (evaluation.performer) on an untrained SAAE: the figures are
the stream's own, checked against what they are computed from."""

import numpy as np
import pytest

pytest.importorskip("torch", reason="exports a random SAAE: pip install '.[train]'")

from motion_style_ros.core.synthetic import synthetic_motion  # noqa: E402
from motion_style_ros.evaluation import metrics, performer  # noqa: E402
from motion_style_ros.evaluation.judges import Judge  # noqa: E402
from motion_style_ros.runtime.saae import Sampler  # noqa: E402
from motion_style_ros.training.saae.export import export_random_model  # noqa: E402

STYLES = ["active", "elderly", "exhausted", "feminine", "masculine", "normal", "youthful"]


@pytest.fixture(scope="module")
def model(tmp_path_factory):
    path = tmp_path_factory.mktemp("saae") / "saae.onnx"
    export_random_model(path, STYLES, "model2")
    return path


def test_windows_cut_whole_clips_of_the_length_and_drop_the_tail():
    walk = synthetic_motion("walk", 30.0, 10.0)
    cut = performer.windows(walk, 4.0)
    assert [w.n_frames for w in cut] == [120, 120]
    np.testing.assert_array_equal(cut[1].rotations, walk.rotations[120:240])


def test_the_report_is_the_streams_own_figures(model):
    real = [("elderly", synthetic_motion("walk", 30.0, 4.0)), ("active", synthetic_motion("run", 30.0, 4.0))]
    judges = [Judge("style")]
    report = performer.evaluate(model, real, judges, minutes=0.2, styles=["elderly", "active"], progress=False)
    rows, summary = report["styles"], report["summary"]
    assert set(rows) == {"elderly", "active"}
    sampler = Sampler(model)
    sampler.set_style("elderly")
    stream = sampler.motion(12.0)  # the same seed and style: the same stream
    assert rows["elderly"]["frames"] == stream.n_frames == 360
    assert rows["elderly"]["largest_jump_m"] == pytest.approx(metrics.largest_jump(stream))
    real_jump = max(metrics.largest_jump(m) for _, m in real)
    assert summary["real_largest_jump_m"] == pytest.approx(real_jump)
    assert rows["elderly"]["seams_over_real"] == int((metrics.joint_jumps(stream) > real_jump).sum())
    assert rows["elderly"]["foot_skating_real_median"] == pytest.approx(metrics.foot_skating(real[0][1]))
    judged = judges[0].judge(performer.windows(stream))
    assert rows["elderly"]["recognised_1"] == pytest.approx(np.mean([j == "elderly" for j in judged.labels]))
    assert summary["recognised_1"] == pytest.approx((rows["elderly"]["recognised_1"] + rows["active"]["recognised_1"]) / 2)
