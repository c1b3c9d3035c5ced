"""Whole clips through a streaming session, as a node would stream them: the one offline path
shared by ``motion-style stylize`` and ``motion-style eval``, with the sessions' defaults
(:data:`motion_style_ros.runtime.defaults.DEFAULTS`, the node's) unless a caller passes others.

A stylizer here is ``(source Motion on the canonical skeleton, target style) -> Motion``. Backends
register a factory in :data:`STYLIZERS` as they land.
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


def recurrent(model: str | None = None, alpha: float = 1.0, threads: int = 1, **session) -> Stylizer:
    """The recurrent (Style-ERD) session; ``session``: more of its settings."""
    from motion_style_ros.runtime.session import RecurrentSession

    return _per_rate(lambda fps: RecurrentSession(model or default_model("recurrent"), input_fps=fps,
                                                  threads=threads, **session), alpha)


def stgcn(model: str | None = None, alpha: float = 1.0, threads: int = 1,
          seed_spread: float = DEFAULTS["seed_spread"], **session) -> Stylizer:
    """The windowed ST-GCN session: latent seed 0, the default window, hop and lookahead."""
    return windowed(model, alpha, threads, seed_spread=seed_spread, **session)[0]


def windowed(model: str | None = None, alpha: float = 1.0, threads: int = 1, seed: int = 0,
             reference: "Motion | None" = None, style: str | None = None,
             seed_spread: float = DEFAULTS["seed_spread"], **session) -> tuple[Stylizer, str | None]:
    """The windowed ST-GCN session with a latent seed, or with a reference clip's style code (read
    by ``style``'s head, by default the style the encoder recognises); the stylizer, and the
    reference's style."""
    from motion_style_ros.runtime.windowed import WindowedSession

    recognised = []

    def make(fps: float | None) -> WindowedSession:
        made = WindowedSession(model or default_model("stgcn"), input_fps=fps, threads=threads,
                               latent_seed=seed, seed_spread=seed_spread, **session)
        if reference is not None:
            recognised.append(made.set_reference(reference, style))
        return made

    stylize = _per_rate(make, alpha)
    return stylize, recognised[0] if recognised else None


STYLIZERS: dict[str, Callable[..., Stylizer]] = {"recurrent": recurrent, "stgcn": stgcn}


def stylizer(backend: str, model: str | None = None, alpha: float = 1.0, threads: int = 1,
             seed_spread: float | None = None, **session) -> Stylizer:
    """A backend's offline stylizer; ``seed_spread`` (stgcn only): see ``WindowedSession``;
    ``session``: more session settings (:meth:`~motion_style_ros.runtime.backends.Backend.settings`
    keeps those a backend takes)."""
    from motion_style_ros.errors import MotionStyleError
    from motion_style_ros.runtime.backends import backend as spec
    from motion_style_ros.runtime.backends import with_feature

    spec(backend)  # an unknown name: one line naming the backends
    if seed_spread is None:
        return STYLIZERS[backend](model=model, alpha=alpha, threads=threads, **session)
    if not spec(backend).latent_seeds:
        raise MotionStyleError(f"a seed spread needs backend {' or '.join(with_feature('latent_seeds'))} "
                               f"(latent seeds); {backend} has none")
    return stgcn(model=model, alpha=alpha, threads=threads, seed_spread=seed_spread, **session)
