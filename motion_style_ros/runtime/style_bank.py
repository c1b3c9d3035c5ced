"""A style bank: styles a user enrols from a few clips of their own, for a model that takes style
codes (the windowed ST-GCN backend), without retraining.

A bank is a JSON file beside the model (``stgcn.onnx`` -> ``stgcn_styles.json``; any path with
``--bank`` or the node's ``style_bank`` parameter). Each entry is the style encoder's code of the
enrolled clips, averaged over the clips, under one head of the encoder: the known style the
encoder's classifier finds the clips closest to (their mean probability), unless the user names one;
or (``mix``) every head's code weighted by the classifier's probabilities.
Codes only mean something to the generator they were made with, so the bank records a digest of
the model's files and is refused by any other model.
"""

from __future__ import annotations

import hashlib
import json
import re
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from motion_style_ros.errors import MotionStyleError

VERSION = 1
MIX = "mix"  # the head of an entry made from every head's code
_NAME = re.compile(r"[a-z0-9][a-z0-9_-]{0,39}")


@dataclass(frozen=True)
class Entry:
    """One enrolled style."""

    code: tuple[float, ...]  # (style_dim,) the generator's input for this style
    head: str  # the encoder head the code was read from (a style of the model)
    clips: tuple[str, ...]  # the file names it was enrolled from
    frames: int  # model frames over all clips
    probabilities: dict[str, float]  # the classifier's mean probabilities of the heads it used


def path_beside(model: Path) -> Path:
    """The default bank file of a model file."""
    return model.with_name(f"{model.stem}_styles.json")


def digest(files: list[Path]) -> str:
    """A short digest of the model files whose codes a bank holds."""
    h = hashlib.sha256()
    for f in files:
        h.update(f.read_bytes())
    return h.hexdigest()[:16]


def check_name(name: str, known: list[str]) -> str:
    """A name a new style may take, or a one-line reason."""
    if not isinstance(name, str) or not _NAME.fullmatch(name):
        raise MotionStyleError(f"style name {name!r}: use 1-40 lowercase letters, digits, '-' or '_', "
                               "starting with a letter or digit")
    if name in known:
        raise MotionStyleError(f"style {name!r} is one the model knows already: {', '.join(known)}")
    return name


def read(path: Path, model_digest: str, style_dim: int, styles: list[str]) -> dict[str, Entry]:
    """The entries of a bank for the model with this digest, or a one-line reason."""
    try:
        raw = json.loads(Path(path).read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise MotionStyleError(f"{path}: no such style bank") from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise MotionStyleError(f"{path}: not a style bank ({type(exc).__name__})") from None
    if not isinstance(raw, dict) or raw.get("version") != VERSION or not isinstance(raw.get("styles"), dict):
        raise MotionStyleError(f"{path}: not a version-{VERSION} style bank")
    if raw.get("model_digest") != model_digest:
        raise MotionStyleError(f"{path}: made for another model ({raw.get('model')!r}, digest "
                               f"{raw.get('model_digest')}); enrol the styles again for this one")
    entries = {}
    for name, e in raw["styles"].items():
        try:
            entry = Entry(tuple(float(v) for v in e["code"]), str(e["head"]), tuple(e["clips"]),
                          int(e["frames"]), {str(k): float(v) for k, v in e["probabilities"].items()})
        except (KeyError, TypeError, ValueError):
            raise MotionStyleError(f"{path}: style {name!r} is not a valid entry") from None
        if len(entry.code) != style_dim or not np.isfinite(entry.code).all() or entry.head not in [*styles, MIX]:
            raise MotionStyleError(f"{path}: style {name!r} has no finite {style_dim}-value code "
                                   "from one of the model's heads")
        entries[check_name(name, styles)] = entry
    return entries


def write(path: Path, entries: dict[str, Entry], model: str, model_digest: str) -> None:
    """The bank file (entries in name order)."""
    body = {"version": VERSION, "model": model, "model_digest": model_digest,
            "styles": {k: {**asdict(entries[k]), "code": [round(v, 7) for v in entries[k].code]}
                       for k in sorted(entries)}}
    try:
        Path(path).write_text(json.dumps(body, indent=1) + "\n", encoding="utf-8")
    except OSError as exc:
        raise MotionStyleError(f"{path}: cannot write the style bank ({exc.strerror}); "
                               "choose another file with --bank") from None


def enrol(codes: list[np.ndarray], logits: list[np.ndarray], frames: list[int], clips: list[str],
          styles: list[str], head: str | None = None) -> Entry:
    """An entry from the style encoder's outputs on each clip (``codes`` ``(S, D)`` and ``logits``
    ``(S,)`` per clip): the codes of one head averaged over the clips, weighted by their frames."""
    if not codes:
        raise MotionStyleError("enrolling a style needs at least one clip")
    p = np.stack([np.exp(x - x.max()) / np.exp(x - x.max()).sum() for x in logits])
    mean_p = p.mean(axis=0)
    w = np.asarray(frames, dtype=float)
    if head == MIX:  # each clip's codes under every head, weighted by its own probabilities
        per_clip = np.einsum("ns,nsd->nd", p, np.stack(codes))
        name = MIX
    else:
        if head is None:
            k = int(np.argmax(mean_p))
        elif head in styles:
            k = styles.index(head)
        else:
            raise MotionStyleError(f"head {head!r} is neither {MIX} nor a style of the model: {', '.join(styles)}")
        per_clip, name = np.stack([c[k] for c in codes]), styles[k]
    code = (per_clip * w[:, None]).sum(axis=0) / w.sum()
    top = np.argsort(mean_p)[::-1][:3]
    return Entry(tuple(float(v) for v in code), name, tuple(clips), int(w.sum()),
                 {styles[i]: round(float(mean_p[i]), 4) for i in top})
