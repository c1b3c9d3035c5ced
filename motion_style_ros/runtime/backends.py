"""The stylizer backends: one entry each, asked by every caller (node, CLI, evaluation, bench)
instead of comparing backend names. Adding a backend is one entry here, its model-step module (a
:class:`~motion_style_ros.runtime.model_step.ModelStep` and the :class:`~motion_style_ros.runtime.stream.StreamSession`
subclass that builds it, with the backend's own controls), its contract in
:mod:`~motion_style_ros.runtime.contract`, its trainer and its card."""

from __future__ import annotations

import importlib
from dataclasses import dataclass
from pathlib import Path

from motion_style_ros.errors import MotionStyleError
from motion_style_ros.runtime.defaults import StreamSettings


@dataclass(frozen=True)
class Backend:
    name: str
    summary: str
    default_model: str  # the shipped model's file name in models/
    session: str  # "module:Class" of its streaming session (imported when first needed)
    latent_seeds: bool = False  # latent_seed / seed_spread change its style codes
    reference_clips: bool = False  # a reference clip's style code can replace a style's
    style_bank: bool = False  # styles enrolled from clips (motion-style style add)
    lookahead: bool = False  # windows: outputs wait for lookahead model frames

    def settings(self, values: dict) -> dict:
        """The entries of ``values`` (session settings by keyword) that this backend's session
        takes: ``window``, ``hop`` and ``lookahead`` only with windows, ``seed_spread`` only with
        seeds, ``bank`` only with a style bank."""
        takes = {"window": self.lookahead, "hop": self.lookahead, "lookahead": self.lookahead,
                 "seed_spread": self.latent_seeds, "bank": self.style_bank}
        return {k: v for k, v in values.items() if takes.get(k, True)}

    def session_class(self) -> type:
        module, name = self.session.split(":")
        return getattr(importlib.import_module(module), name)

    def open_session(self, model: str | Path | None = None, settings: StreamSettings | None = None,
                     **options):
        """This backend's session on ``model`` (default: its shipped one) with the stream
        ``settings`` (default: :data:`~motion_style_ros.runtime.defaults.DEFAULTS`') and the
        session's own ``options`` (``performers``, ``input_fps``, ``threads``, ``window``, ...;
        windows and seeds only where the backend has them: :meth:`settings`)."""
        return self.session_class()(model or self.default_model, settings=settings, **self.settings(options))


BACKENDS: dict[str, Backend] = {
    "recurrent": Backend("recurrent", "Style-ERD, frame by frame", "style_erd.onnx",
                         "motion_style_ros.runtime.recurrent:RecurrentSession"),
    "stgcn": Backend("stgcn", "ST-GCN windows blended by overlap-add, latent seeds and reference clips",
                     "stgcn.onnx", "motion_style_ros.runtime.stgcn:StgcnSession",
                     latent_seeds=True, reference_clips=True, style_bank=True, lookahead=True),
    "most": Backend("most", "MoST (Kim et al. 2024): windows restyled like a reference clip of any action or a "
                    "style's mean features, blended by overlap-add", "most.onnx",
                    "motion_style_ros.runtime.most:MostSession", reference_clips=True, style_bank=True,
                    lookahead=True),
    "saae": Backend("saae", "sequence adversarial autoencoder (ESANN 2018): windows re-decoded with a style "
                    "label (Model1) or a reference clip's style code (Model2), blended by overlap-add",
                    "saae_model2_5d.onnx", "motion_style_ros.runtime.saae:SaaeSession",
                    reference_clips=True, lookahead=True),
}


def backend(name: str) -> Backend:
    """The backend called ``name``, or a one-line error naming the ones there are."""
    if name not in BACKENDS:
        raise MotionStyleError(f"unknown backend {name!r}; allowed: {', '.join(BACKENDS)}")
    return BACKENDS[name]


def with_feature(feature: str) -> list[str]:
    """The backends that have ``feature`` (a flag of :class:`Backend`), e.g. for an error message."""
    return [b.name for b in BACKENDS.values() if getattr(b, feature)]
