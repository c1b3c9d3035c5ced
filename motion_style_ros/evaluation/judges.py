"""The shipped style and content judges at run time (ONNX Runtime, no torch)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from motion_style_ros.core.features import FEATURE_VERSION, encode
from motion_style_ros.core.motion import Motion
from motion_style_ros.core.resample import resample
from motion_style_ros.core.skeleton import canonical
from motion_style_ros.errors import MotionStyleError
from motion_style_ros.runtime.onnx_model import OnnxModel, model_path, read_card


@dataclass
class Judgement:
    """One row per judged clip."""

    labels: list[str]  # predicted labels
    probabilities: np.ndarray  # (N, classes), columns in the judge's label order
    embeddings: np.ndarray  # (N, E)


KINDS = ("style", "content")


def judge_file(kind: str, panel: int = 1) -> str:
    """The shipped judge of ``kind`` on ``panel`` 1 or 3 (may guide training choices) or 2 (reports
    only; see :mod:`motion_style_ros.models.judge`)."""
    return f"judge_{kind}.onnx" if panel == 1 else f"judge{panel}_{kind}.onnx"


class Judge:
    """A shipped judge (``kind`` "style" or "content", on ``panel`` 1 or 2) or any judge ONNX file
    with its card."""

    def __init__(self, kind_or_path: str | Path, threads: int = 1, panel: int = 1) -> None:
        name = str(kind_or_path)
        path = model_path(judge_file(name, panel) if name in KINDS else name)
        self.card = read_card(path)
        if self.card.get("feature_version") != FEATURE_VERSION:
            raise MotionStyleError(
                f"{path}: made for feature version {self.card.get('feature_version')}, this package "
                f"computes version {FEATURE_VERSION}; retrain it (motion-style train judges)"
            )
        self.labels: list[str] = list(self.card["labels"])
        self.fps = float(self.card["fps"])
        self.model = OnnxModel(path, threads)

    def judge_features(self, features: list[np.ndarray]) -> Judgement:
        """Judge ``encode()`` features at the judge's frame rate, each clip whole."""
        logits, embeddings = [], []
        for f in features:
            out = self.model.run(features=np.asarray(f, dtype=np.float32)[None])
            logits.append(out["logits"][0])
            embeddings.append(out["embedding"][0])
        if not logits:
            return Judgement([], np.zeros((0, len(self.labels))), np.zeros((0, 0), dtype=np.float32))
        logits = np.array(logits, dtype=np.float64)
        probs = np.exp(logits - logits.max(axis=-1, keepdims=True))
        probs /= probs.sum(axis=-1, keepdims=True)
        return Judgement([self.labels[i] for i in probs.argmax(-1)], probs, np.array(embeddings))

    def judge(self, motions: list[Motion]) -> Judgement:
        """Judge canonical-skeleton motions (resampled to the judge's frame rate when needed)."""
        return self.judge_features([self.features(m) for m in motions])

    def features(self, motion: Motion) -> np.ndarray:
        names = canonical().names
        if motion.skeleton.names != names:
            raise MotionStyleError(
                f"the judges need motions on the canonical {len(names)}-joint skeleton; got a "
                f"{motion.skeleton.n_joints}-joint skeleton (retarget the motion first)"
            )
        return encode(resample(motion, self.fps))
