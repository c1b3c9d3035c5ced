"""A style bank: styles a user enrols from a few clips of their own, for a model that takes its
style from a code or from features of a clip (the stgcn and most backends), without retraining.

A bank is a JSON file beside the model (``stgcn.onnx`` -> ``stgcn_styles.json``; any path with
``--bank`` or the node's ``style_bank`` parameter). An entry holds what the model's style encoder
reads from the enrolled clips, averaged over the clips (weighted by their frames):

- **stgcn**: the code under one head of the encoder: the known style the encoder's classifier
  finds the clips closest to (their mean probability), unless the user names one; or (``mix``)
  every head's code weighted by the classifier's probabilities.
- **most**: the clips' own style features (``features``: body-part style and mean content
  features, as a reference clip gives them); MoST reads style from any motion, so no head.

Codes only mean something to the model they were made with, so the bank records a digest of the
model's files and is refused by any other model.
"""

from __future__ import annotations

import hashlib
import json
import re
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from motion_style_ros.errors import MotionStyleError
from motion_style_ros.io import files

VERSION = 1
MIX = "mix"  # the head of an entry made from every head's code
FEATURES = "features"  # the head of an entry that holds the clips' own style features (most)
_NAME = re.compile(r"[a-z0-9][a-z0-9_-]{0,39}")


@dataclass(frozen=True)
class Entry:
    """One enrolled style."""

    code: tuple[float, ...]  # (style_dim,) the generator's input for this style
    head: str  # the encoder head the code was read from (a style of the model)
    clips: tuple[str, ...]  # the file names it was enrolled from
    frames: int  # model frames over all clips
    # how close the clips are to the model's styles (the three closest): the classifier's mean
    # probabilities (stgcn), or shares of the inverse squared feature distances (most)
    probabilities: dict[str, float]


def path_beside(model: Path) -> Path:
    """The default bank file of a model file."""
    return model.with_name(f"{model.stem}_styles.json")


def digest(models: list[Path]) -> str:
    """A short digest of the model files whose codes a bank holds."""
    h = hashlib.sha256()
    for f in models:
        h.update(files.read_bytes(f, "model"))
    return h.hexdigest()[:16]


def check_name(name: str, known: list[str]) -> str:
    """A name a new style may take, or a one-line reason."""
    if not isinstance(name, str) or not _NAME.fullmatch(name):
        raise MotionStyleError(f"style name {name!r}: use 1-40 lowercase letters, digits, '-' or '_', "
                               "starting with a letter or digit")
    if name in known:
        raise MotionStyleError(f"style {name!r} is one the model knows already: {', '.join(known)}")
    return name


def read(path: Path, model_digest: str, style_dim: int, styles: list[str],
         heads: list[str] | None = None) -> dict[str, Entry]:
    """The entries of a bank for the model with this digest (codes of ``style_dim`` values read
    under one of ``heads``, default the styles and ``mix``), or a one-line reason."""
    heads = [*styles, MIX] if heads is None else heads
    raw = _load(path)
    if raw.get("model_digest") != model_digest:
        raise MotionStyleError(f"{path}: made for another model ({raw.get('model')!r}, digest "
                               f"{raw.get('model_digest')}); enrol the styles again for this one")
    entries = {}
    for name, e in raw["styles"].items():
        try:
            entry = Entry(tuple(float(v) for v in e["code"]), str(e["head"]), tuple(e["clips"]),
                          int(e["frames"]), {str(k): float(v) for k, v in e["probabilities"].items()})
        # KeyError: a field missing; TypeError: a field of another type (a number for a list, a
        # list in a code); ValueError: text for a number; AttributeError: probabilities not a
        # mapping; OverflowError: frames infinite, a number beyond the floats
        except (KeyError, TypeError, ValueError, AttributeError, OverflowError):
            raise MotionStyleError(f"{path}: style {name!r} is not a valid entry") from None
        if (entry.frames < 0 or not all(isinstance(c, str) for c in entry.clips)
                or not np.isfinite(list(entry.probabilities.values())).all()):
            raise MotionStyleError(f"{path}: style {name!r} is not a valid entry (frames, clips or "
                                   "probabilities)")
        if len(entry.code) != style_dim or not np.isfinite(entry.code).all() or entry.head not in heads:
            raise MotionStyleError(f"{path}: style {name!r} has no finite {style_dim}-value code "
                                   "from one of the model's heads")
        entries[check_name(name, styles)] = entry
    return entries


def _load(path: Path) -> dict:
    """A bank file's JSON, checked to be a bank of this version, or a one-line reason."""
    if not Path(path).exists():
        raise MotionStyleError(f"{path}: no such style bank")
    try:
        raw = json.loads(files.read_bytes(path, "style bank").decode("utf-8"))
    # ValueError: JSONDecodeError, an int of over 4300 digits; RecursionError: nested too deep
    except (UnicodeDecodeError, ValueError, RecursionError) as exc:
        raise MotionStyleError(f"{path}: not a style bank ({type(exc).__name__})") from None
    if not isinstance(raw, dict) or raw.get("version") != VERSION or not isinstance(raw.get("styles"), dict):
        raise MotionStyleError(f"{path}: not a version-{VERSION} style bank")
    return raw


def names_beside(model: Path) -> list[str]:
    """The styles of the bank beside ``model`` (what its sessions load by default), none without one."""
    beside = path_beside(model)
    return list(_load(beside)["styles"]) if beside.is_file() else []


def open_bank(bank: str | Path | None, model: Path, model_digest: str, style_dim: int, styles: list[str],
              heads: list[str] | None = None) -> tuple[Path | None, dict[str, Entry]]:
    """The bank a session of ``model`` uses (``bank``, else the model's own beside it if there is
    one; None: none) and its entries (:func:`read`)."""
    beside = path_beside(model)
    path = Path(bank) if bank is not None else beside if beside.exists() else None
    return path, ({} if path is None else read(path, model_digest, style_dim, styles, heads))


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


def enrol_features(features: list[np.ndarray], distances: list[np.ndarray], frames: list[int], clips: list[str],
                   styles: list[str]) -> Entry:
    """An entry of the clips' own style features (``features`` per clip, any shape; ``distances``
    ``(S,)`` per clip: its squared distance to each style's mean features), averaged over the clips
    weighted by their frames."""
    if not features:
        raise MotionStyleError("enrolling a style needs at least one clip")
    w = np.asarray(frames, dtype=float)
    code = np.einsum("n,nd->d", w, np.stack([f.ravel() for f in features])) / w.sum()
    near = 1.0 / np.maximum(np.stack(distances), 1e-12)
    near = (near / near.sum(axis=1, keepdims=True)).mean(axis=0)
    top = np.argsort(near)[::-1][:3]
    return Entry(tuple(float(v) for v in code), FEATURES, tuple(clips), int(w.sum()),
                 {styles[i]: round(float(near[i]), 4) for i in top})
