"""What the timing targets of ``motion-style bench`` share: the --performers counts, the timed model's
file (with how to get the shipped one) and the line naming it. Light at import time."""

from motion_style_ros.runtime.backends import BACKENDS

DEFAULT_MODEL = BACKENDS["recurrent"].default_model


def model_file(name: str):
    """The model's path; a missing shipped model says how to get one."""
    from motion_style_ros.errors import MotionStyleError
    from motion_style_ros.runtime.onnx_model import model_path

    try:
        return model_path(name)
    except MotionStyleError as exc:
        if name != DEFAULT_MODEL:
            raise
        raise MotionStyleError(
            f"{exc}; train it with 'motion-style train recurrent', or time another model with "
            "--model (e.g. a random-weight one from "
            "motion_style_ros.training.recurrent.export_random_model)"
        ) from None


def print_model(path, card: dict) -> None:
    """Which model was timed, and whether it is a random-weight stand-in."""
    from motion_style_ros.runtime.onnx_model import models_dir

    trained = card.get("training", {}).get("data", "unknown data")
    print(f"model: {path} ({card.get('name', path.stem)}, trained on: {trained})")
    if "random" in str(trained):
        shipped = ("" if (models_dir() / DEFAULT_MODEL).is_file()
                   else f" (models/{DEFAULT_MODEL} does not exist yet)")
        print(f"note: a random-weight model{shipped}: the timings hold for a model of its size only")


def performer_counts(text: str) -> list[int]:
    """``--performers``' counts: whole numbers separated by commas, or a one-line error."""
    from motion_style_ros.errors import MotionStyleError

    try:
        return [int(n) for n in text.split(",")]
    except ValueError:
        raise MotionStyleError(f"--performers takes whole numbers separated by commas, got {text!r}") from None
