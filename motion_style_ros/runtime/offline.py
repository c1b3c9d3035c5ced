"""Whole clips through a streaming session, as a node would stream them: the one offline path
shared by ``motion-style stylize`` and ``motion-style eval``, with the sessions' defaults
(:data:`motion_style_ros.runtime.defaults.DEFAULTS`, the node's) unless a caller passes others.

A stylizer here is ``(source Motion on the canonical skeleton, target style) -> Motion``: the
session of the backend's registry entry (:func:`with_reference`).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING

from motion_style_ros.runtime.defaults import DEFAULTS

if TYPE_CHECKING:  # the CLI imports this module to build its parser: keep it light
    from motion_style_ros.core.motion import Motion

Stylizer = Callable[["Motion", str], "Motion"]


def _per_rate(make: Callable[[float | None], object], alpha: float) -> Stylizer:
    """One streaming session per input frame rate (``make(fps)``), restarted for every clip."""
    sessions = {None: make(None)}  # fail now, in one line, on a missing or bad model

    def stylize(source: "Motion", target_style: str) -> "Motion":
        if source.fps not in sessions:
            sessions[source.fps] = make(source.fps)
        return sessions[source.fps].run(source, target_style, alpha)

    return stylize


def default_model(backend: str) -> str:
    """The shipped model file of a backend."""
    from motion_style_ros.runtime.backends import backend as spec

    return spec(backend).default_model


def with_reference(backend: str, model: str | None = None, alpha: float = DEFAULTS["alpha"], threads: int = 1,
                   reference: "Motion | None" = None, style: str | None = None, seed: int = 0,
                   **session) -> tuple[Stylizer, str | None]:
    """A backend's session (the registry's class, its default settings unless ``session`` says
    otherwise), with latent seed ``seed`` where the backend has seeds and a reference clip's style
    where one is given (as the input of ``style``, by default the style the clip is recognised
    as); the stylizer, and the reference's style."""
    from motion_style_ros.runtime.backends import backend as spec

    made_by = spec(backend)
    seeds = {"latent_seed": seed} if made_by.latent_seeds else {}
    recognised = []

    def make(fps: float | None):
        made = made_by.open_session(model, input_fps=fps, threads=threads, **seeds, **session)
        if reference is not None:
            recognised.append(made.set_reference(reference, style))
        return made

    stylize = _per_rate(make, alpha)
    return stylize, recognised[0] if recognised else None


def stylizer(backend: str, model: str | None = None, alpha: float = DEFAULTS["alpha"], threads: int = 1,
             seed_spread: float | None = None, **session) -> Stylizer:
    """A backend's offline stylizer; ``seed_spread`` (backends with latent seeds): see
    ``StgcnSession``; ``session``: more session settings
    (:meth:`~motion_style_ros.runtime.backends.Backend.settings` keeps those a backend takes)."""
    from motion_style_ros.errors import MotionStyleError
    from motion_style_ros.runtime.backends import backend as spec
    from motion_style_ros.runtime.backends import with_feature

    made_by = spec(backend)  # an unknown name: one line naming the backends
    if seed_spread is not None:
        if not made_by.latent_seeds:
            raise MotionStyleError(f"a seed spread needs backend {' or '.join(with_feature('latent_seeds'))} "
                                   f"(latent seeds); {backend} has none")
        session["seed_spread"] = seed_spread
    return with_reference(backend, model, alpha, threads, **session)[0]
