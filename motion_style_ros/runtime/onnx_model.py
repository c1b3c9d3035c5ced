"""A small ONNX Runtime wrapper shared by the stylizers and the judges (CPU, no torch)."""

from __future__ import annotations

import functools
import json
import math
from pathlib import Path

import numpy as np

from motion_style_ros.errors import MotionStyleError
from motion_style_ros.io import files

PACKAGE = "motion_style_ros"


def models_dir() -> Path:
    """The shipped ``models/`` folder: the source tree's (checkouts, editable installs) if present,
    else ``<prefix>/share/motion_style_ros/models`` of the prefix the package is installed in
    (``<prefix>/lib/pythonX.Y/site-packages/motion_style_ros``: pip and colcon alike)."""
    here = Path(__file__).resolve()
    source = here.parents[2] / "models"
    return source if source.is_dir() else here.parents[5] / "share" / PACKAGE / "models"


def model_path(name: str) -> Path:
    """A shipped model's path by file name, or a path given by the user, checked to exist."""
    path = Path(name)
    if not path.is_file() and path.parent == Path("."):
        path = models_dir() / name
    if not path.exists():
        raise MotionStyleError(f"{path}: model file not found")
    return files.check(path, "model")


def _count(low: int):
    return (int,), lambda v: not isinstance(v, bool) and v >= low, f"a whole number of at least {low}"


def _names(v) -> bool:
    return all(isinstance(x, str) and x for x in v)


# What the runtime reads from a card, where a card has it: (types, check, what it must be).
CARD_TYPES = {
    "styles": ((list,), _names, "a list of style names"),
    "labels": ((list,), _names, "a list of names"),
    "fps": ((int, float), lambda v: not isinstance(v, bool) and v > 0, "a positive number"),
    "window": _count(1), "frames_multiple": _count(1), "min_frames": _count(1),
    "style_dim": _count(0), "content_dim": _count(0), "latent_dim": _count(0), "state_size": _count(0),
    "feature_dim": _count(0), "style_width": _count(0), "embedding_size": _count(0),
    "name": ((str,), bool, "a name"), "kind": ((str,), bool, "a name"),
    "neutral_style": ((str,), bool, "a style name"), "variant": ((str,), bool, "a name"),
    "files": ((dict,), lambda v: all(isinstance(x, str) for x in v.values()), "file names by role"),
}


def _no_constant(name: str):
    raise ValueError(f"{name} is not a number a card may hold")


def _finite(text: str) -> float:
    value = float(text)
    if not math.isfinite(value):  # 1e400
        raise ValueError(f"{text[:20]} is beyond the floats")
    return value


def read_card(model: Path) -> dict:
    """The JSON model card next to a model (``x.onnx`` -> ``x.json``): a JSON object without NaN or
    Infinity, whose fields the runtime reads (:data:`CARD_TYPES`) have their types."""
    card = Path(model).with_suffix(".json")
    if not card.exists():
        raise MotionStyleError(f"{card}: model card not found (it ships beside {Path(model).name})")
    try:
        data = json.loads(files.read_bytes(card, "card").decode("utf-8"), parse_constant=_no_constant,
                          parse_float=_finite)
    except UnicodeDecodeError:
        raise MotionStyleError(f"{card}: not a text file (a model card is JSON)") from None
    except json.JSONDecodeError as exc:  # before ValueError: it is one
        raise MotionStyleError(f"{card}: not valid JSON ({exc})") from None
    except ValueError as exc:  # NaN, Infinity, 1e400
        raise MotionStyleError(f"{card}: not a model card ({exc})") from None
    except RecursionError:
        raise MotionStyleError(f"{card}: not a model card (JSON nested too deeply)") from None
    if not isinstance(data, dict):
        raise MotionStyleError(f"{card}: not a model card (a JSON object is)")
    for key, (types, ok, what) in CARD_TYPES.items():
        if key in data and not (isinstance(data[key], types) and ok(data[key])):
            raise MotionStyleError(f"{card}: {key} must be {what}, found {str(data[key])[:40]!r}")
    if data.get("kind") in RENAMED_KINDS:  # a card written before its kind took the backend's name
        data["kind"] = RENAMED_KINDS[data["kind"]]
    return data


RENAMED_KINDS = {"windowed": "stgcn"}  # a card's kind is its backend's name


def neutral_style(card: dict) -> str:
    """The style a stream starts in: the card's ``neutral_style``, else its first style."""
    return card.get("neutral_style", card["styles"][0])


class OnnxModel:
    """One inference session on the CPU with its input and output names.

    Models of the same file (and thread count) share one ORT session in a process: a node with
    several performers then holds the weights once, and they stay in the CPU's caches between
    performers (ORT's ``run`` may be called from any thread).
    """

    def __init__(self, path: str | Path, threads: int = 1) -> None:
        # 0 would let ONNX Runtime take every core: for one small model per frame, it never pays
        if isinstance(threads, bool) or not (isinstance(threads, int) and threads >= 1):
            raise MotionStyleError(f"ONNX Runtime threads must be a whole number, at least 1; got {threads!r}")
        self.path = Path(path)
        try:
            stat = self.path.stat()
        except OSError as exc:
            raise MotionStyleError(f"{self.path}: cannot load ONNX model ({exc.strerror})") from None
        self.session = _session(str(self.path.resolve()), stat.st_mtime_ns, stat.st_size, threads)
        self.input_names = [i.name for i in self.session.get_inputs()]
        self.output_names = [o.name for o in self.session.get_outputs()]

    def run(self, **inputs: np.ndarray) -> dict[str, np.ndarray]:
        """Outputs by name for inputs given by name."""
        missing = set(self.input_names) - set(inputs)
        if missing:
            raise MotionStyleError(f"{self.path.name}: missing inputs {', '.join(sorted(missing))}")
        return dict(zip(self.output_names, self.session.run(self.output_names, inputs)))


@functools.lru_cache(maxsize=16)
def _session(path: str, mtime_ns: int, size: int, threads: int):
    """An ORT session per file version (a re-exported file gets a new one) and thread count."""
    import onnxruntime as ort

    options = ort.SessionOptions()
    # Sessions run beside ROS callbacks and other sessions: by default ORT would claim every core.
    options.intra_op_num_threads = threads
    options.inter_op_num_threads = 1
    try:
        return ort.InferenceSession(path, options, providers=["CPUExecutionProvider"])
    except Exception as exc:  # ORT raises its own unexported exception types
        raise MotionStyleError(f"{path}: cannot load ONNX model ({exc})") from None


def record_metrics(model: Path, key: str, metrics: dict) -> Path:
    """Store measured ``metrics`` under ``metrics[key]`` of the model's card (with the command
    that measured them inside), so the card's numbers are the last ones someone ran."""
    card = read_card(model)
    card.setdefault("metrics", {})[key] = metrics
    path = Path(model).with_suffix(".json")
    path.write_text(json.dumps(card, indent=2) + "\n")
    return path
