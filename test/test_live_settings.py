"""The stylizer's live parameters without ROS (runtime.live_settings): a change is checked without
taking effect, taken in order on the streams' thread, and a bad start value is one line."""

import pytest

from motion_style_ros.errors import MotionStyleError
from motion_style_ros.runtime import stylizer_settings
from motion_style_ros.runtime.backends import BACKENDS
from motion_style_ros.runtime.live_settings import LiveSettings
from motion_style_ros.runtime.recurrent import RecurrentSession

VALUES = {p.name: p.default for p in stylizer_settings.PARAMETERS} | {"target_style": "normal"}


@pytest.fixture(scope="module")
def session():
    return RecurrentSession("style_erd.onnx")


def test_a_change_is_checked_then_applied_in_order(session):
    live = LiveSettings([session], BACKENDS["recurrent"], VALUES, print)
    assert "alpha must be of type double" in live.check({"alpha": "high"}) and live.values["alpha"] == 1.0
    assert "bouncy" in live.check({"target_style": "bouncy"})
    assert "reference" in live.check({"reference": "clip.bvh"})  # recurrent takes no reference clip
    assert live.check({"alpha": 0.5, "target_style": "elderly"}) is None
    live.accept({"alpha": 0.5})
    live.accept({"target_style": "elderly"})
    assert live.values["alpha"] == 1.0 and len(live.pending) == 2  # nothing applied yet
    live.apply_pending(revert=lambda path: pytest.fail("nothing to revert"))
    assert live.values["alpha"] == 0.5 and live.values["target_style"] == "elderly" and not live.pending


def test_a_bad_start_value_is_one_line_naming_the_parameter(session):
    with pytest.raises(MotionStyleError, match="^parameter target_style: .*bouncy"):
        LiveSettings([session], BACKENDS["recurrent"], VALUES | {"target_style": "bouncy"}, print)
