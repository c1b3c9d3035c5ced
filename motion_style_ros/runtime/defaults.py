"""One source of the streaming sessions' defaults: the session classes' keyword defaults, the
stylizer node's parameter declarations, ``motion-style stylize``, ``eval`` and ``bench`` all read
:data:`DEFAULTS`, so a clip stylized offline and the same clip streamed through the node come out
the same. The values are the node's: the stylized root follows the performer's (2 s), and the
windowed backend looks 8 model frames (267 ms) ahead."""

from __future__ import annotations

from dataclasses import dataclass, fields, replace

from motion_style_ros.errors import MotionStyleError

DEFAULTS: dict[str, float | int | bool] = {
    "alpha": 1.0,  # the style's intensity: 0 = the performer's own motion, 1 = the full style
    "blend_seconds": 0.3,  # s a style, alpha, mix, seed or reference change blends over
    "gap_seconds": 0.5,  # s between two stamps beyond which the stream restarts
    "follow_seconds": 2.0,  # s time constant pulling the stylized trajectory towards the input's
    "foot_lock": True,  # feet the input plants stay planted
    "ground": True,  # planted ankles moved to the training data's height on the way in, back out
    "conform": True,  # arm rolls and size measured and conformed to the training data's
    "pipelined": False,  # the output waits for no model frame of its own input frame
    "hop": 4,  # windowed: model frames between two windows
    "lookahead": 8,  # windowed: model frames of the future each output frame waits for
    "seed_spread": 1.0,  # windowed: how far seeds' codes lie from their style's mean (1: as trained)
}


@dataclass(frozen=True)
class StreamSettings:
    """How a stream session conditions, restyles and places every stream, whatever its backend
    (:class:`~motion_style_ros.runtime.stream.StreamSession`): the node's parameters of the same
    names, and the defaults of ``stylize``, ``eval`` and ``bench``. ``phase_seconds`` (in [0, 1 /
    model fps)): how much later than the stream's start the model's clock ticks, so that sessions
    serving several streams in one process run their model frames on different input frames."""

    blend_seconds: float = DEFAULTS["blend_seconds"]
    gap_seconds: float = DEFAULTS["gap_seconds"]
    follow_seconds: float | None = DEFAULTS["follow_seconds"]
    foot_lock: bool = DEFAULTS["foot_lock"]
    ground: bool = DEFAULTS["ground"]
    conform: bool = DEFAULTS["conform"]
    pipelined: bool = DEFAULTS["pipelined"]
    phase_seconds: float = 0.0

    @classmethod
    def of(cls, settings: StreamSettings | None = None, changes: dict | None = None) -> StreamSettings:
        """``settings`` (default: the defaults) with ``changes`` by name; a name that is no setting
        is one line naming them."""
        unknown = sorted(set(changes or {}) - {f.name for f in fields(cls)})
        if unknown:
            raise MotionStyleError(f"no stream setting {', '.join(unknown)}; the settings are "
                                   f"{', '.join(f.name for f in fields(cls))}")
        return replace(settings or cls(), **(changes or {}))
