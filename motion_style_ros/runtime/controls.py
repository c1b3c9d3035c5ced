"""What a stylizer session is asked to do, per performer: target style, an optional second style
with a mix weight, alpha (the style's intensity) and the part alphas that scale it per body part
(:mod:`motion_style_ros.core.intensity`).

A change never lands at once: the model's ``style`` input and each part's intensity move from where
they are to the new target along a smoothstep over ``blend_seconds`` of stream time. Every style
branch of the model runs at every step, so re-weighting them is continuous and the blend makes it
gradual.
"""

from __future__ import annotations

import numpy as np

from motion_style_ros.core.easing import smoothstep
from motion_style_ros.core.intensity import PARTS, check_part_alpha
from motion_style_ros.errors import MotionStyleError
from motion_style_ros.runtime.defaults import DEFAULTS


def unit_interval(value: float, what: str) -> float:
    try:
        value = float(value)
    except (TypeError, ValueError):
        raise MotionStyleError(f"{what} must be a number in [0, 1], got {value!r}") from None
    if not 0.0 <= value <= 1.0:  # also rejects NaN
        raise MotionStyleError(f"{what} must be in [0, 1], got {value:g}")
    return value


class Controls:
    """Targets and blends of ``performers`` performers over the model's ``styles``.

    Each performer's controls are one vector: style weights (S) then each part's intensity, alpha
    times the part's alpha (one per :data:`~motion_style_ros.core.intensity.PARTS`). A blend runs
    from the vector in use when the change came (even mid-blend) to the new target.
    """

    def __init__(self, styles: list[str], performers: int, style: str, blend_seconds: float) -> None:
        if not (np.isfinite(blend_seconds) and blend_seconds >= 0):
            raise MotionStyleError(f"blend time must be 0 s or more, got {blend_seconds}")
        self.styles = list(styles)
        self.performers = performers
        self.blend_seconds = float(blend_seconds)
        self._primary = np.full(performers, self.style_index(style))
        self._secondary = np.zeros(performers, dtype=int)
        self._mix = np.zeros(performers)
        self._alpha = np.full(performers, DEFAULTS["alpha"])
        self._parts = np.ones((performers, len(PARTS)))
        self._from = self._target()
        self._progress = np.ones(performers)  # 1: blend done
        self._settled: tuple[np.ndarray, np.ndarray] | None = None  # the inputs once every blend is done

    def style_index(self, style: str) -> int:
        if style not in self.styles:
            raise MotionStyleError(
                f"unknown style {style!r}; this model knows: {', '.join(self.styles)}"
            )
        return self.styles.index(style)

    def which(self, performer: int | None) -> slice | int:
        """All performers (None) or one, checked."""
        if performer is None:
            return slice(None)
        if not (isinstance(performer, (int, np.integer)) and 0 <= performer < self.performers):
            raise MotionStyleError(
                f"performer {performer!r} out of range; this session has performers "
                f"0-{self.performers - 1}"
            )
        return int(performer)

    def set_style(self, style: str, performer: int | None = None) -> None:
        k, which = self.style_index(style), self.which(performer)
        self._begin(which)
        self._primary[which] = k

    def set_alpha(self, alpha: float, performer: int | None = None) -> None:
        a, which = unit_interval(alpha, "alpha"), self.which(performer)
        self._begin(which)
        self._alpha[which] = a

    def set_part_alpha(self, values, performer: int | None = None) -> None:
        """Scale alpha per body part: one number in [0, 1] for each of
        :data:`~motion_style_ros.core.intensity.PARTS`."""
        parts, which = check_part_alpha(values), self.which(performer)
        self._begin(which)
        self._parts[which] = parts

    def set_mix(self, style: str | None, weight: float, performer: int | None = None) -> None:
        """Blend a second style in with ``weight`` (0: the target style alone, 1: the second style
        alone); ``style=None`` removes the second style."""
        which = self.which(performer)
        k = 0 if style is None else self.style_index(style)
        w = 0.0 if style is None else unit_interval(weight, "mix weight")
        self._begin(which)
        self._secondary[which], self._mix[which] = k, w

    def snap(self, which: np.ndarray | slice) -> None:
        """Jump to the targets (a performer that starts afresh has nothing to blend from)."""
        self._from[which] = self._target()[which]
        self._progress[which] = 1.0
        self._settled = None

    def advance(self, seconds: float) -> tuple[np.ndarray, np.ndarray]:
        """Move the blends on by ``seconds`` of stream time; the model's ``style`` ``(P, S)``
        float32 input and each part's intensity ``(P, len(PARTS))`` for this step (read-only:
        between changes, every step gets the same arrays)."""
        if self._settled is not None:
            return self._settled
        step = np.inf if self.blend_seconds == 0 else seconds / self.blend_seconds
        self._progress = np.minimum(self._progress + step, 1.0)
        now = self._current()
        styles = len(self.styles)
        inputs = now[:, :styles].astype(np.float32), now[:, styles:].copy()
        if (self._progress >= 1.0).all():
            for a in inputs:
                a.flags.writeable = False
            self._settled = inputs
        return inputs

    def _begin(self, which: slice | int) -> None:
        """Start a blend from the vector in use now (call before changing the target)."""
        self._from[which] = self._current()[which]
        self._progress[which] = 0.0
        self._settled = None

    def _target(self) -> np.ndarray:
        eye = np.eye(len(self.styles))
        mix = self._mix[:, None]
        weights = (1.0 - mix) * eye[self._primary] + mix * eye[self._secondary]
        return np.concatenate([weights, self._alpha[:, None] * self._parts], axis=1)

    def _current(self) -> np.ndarray:
        return self._from + smoothstep(self._progress)[:, None] * (self._target() - self._from)
