"""ONNX export and model cards, shared by every trainer: the TorchScript export under the names of
the model contract (:mod:`motion_style_ros.runtime.contract`), the card fields every model states
alike, and writing a stylizer with its card and its ONNX vs torch parity."""

from __future__ import annotations

import json
import warnings
from collections.abc import Callable
from pathlib import Path

import numpy as np
import torch
from torch import nn

from motion_style_ros.core.features import FEATURE_VERSION, feature_layout
from motion_style_ros.runtime.contract import Contract, check_card
from motion_style_ros.training.data import FPS

OPSET = 17
# A model trained on the Bandai Namco data carries the data's licence (one trained on a user's
# folder, the licence they give it: licence_fields).
LICENCE = {
    "licence": "CC BY-NC 4.0 (inherited from the training data): non-commercial use only",
    "attribution": ('Kobayashi et al., "Motion Capture Dataset for Practical Use of AI-based Motion '
                    'Editing and Stylization", arXiv:2306.08861, 2023'),
}
# CMU's requested acknowledgement, for a model trained with CMU clips (``--unlabelled cmu:NN``)
CMU_ACKNOWLEDGEMENT = ("CMU clips: the data used in this project was obtained from mocap.cs.cmu.edu; the "
                       "database was created with funding from NSF EIA-0196217")


def export_graph(module: nn.Module, example: tuple[torch.Tensor, ...], path: Path, contract: Contract,
                 timed: tuple[str, ...] = (), time_axis: str = "frames", quiet: tuple[str, ...] = ()
                 ) -> None:
    """``module`` (in eval mode) as ONNX at ``path`` with the ``contract``'s input and output names,
    the batch axis dynamic everywhere and the time axis (``time_axis``) too on the ``timed`` names.
    ``quiet``: exporter warnings known to be harmless for this module (message prefixes)."""
    names = (*contract.inputs, *contract.outputs)
    with warnings.catch_warnings():
        # The TorchScript exporter is deprecated in favour of the dynamo one (which needs
        # onnxscript); these networks export the same either way. The tracer warns about shape
        # checks inside the torch modules (nn.LSTM's, for one) that the graph does not need.
        warnings.simplefilter("ignore", DeprecationWarning)
        warnings.simplefilter("ignore", torch.jit.TracerWarning)
        for message in quiet:
            warnings.filterwarnings("ignore", message=message)
        torch.onnx.export(
            module.eval(),
            example,
            str(path),
            input_names=list(contract.inputs),
            output_names=list(contract.outputs),
            dynamic_axes={n: {0: "batch", 1: time_axis} if n in timed else {0: "batch"} for n in names},
            opset_version=OPSET,
            dynamo=False,
        )


def run_onnx(path: Path, contract: Contract, *inputs: np.ndarray) -> list[np.ndarray]:
    """The ONNX model at ``path`` run on ``inputs`` in the ``contract``'s order; its outputs in the
    contract's order (for parity checks against torch)."""
    from motion_style_ros.runtime.onnx_model import OnnxModel

    outputs = OnnxModel(path).run(**dict(zip(contract.inputs, inputs, strict=True)))
    return [outputs[name] for name in contract.outputs]


def licence_fields(training: dict) -> dict:
    """The card's licence and attribution: the user's for a model of their own data (the
    ``licence`` of its training record, :func:`motion_style_ros.training.data.recipe`), else the
    Bandai data's."""
    fields = (dict(LICENCE) if "licence" not in training
              else {"licence": training["licence"], "attribution": f"trained on {training['data']}"})
    specs = [*training.get("config", {}).get("unlabelled", []),
             *training.get("clips", {}).get("pairs", {}).get("clips", [])]
    if any(str(spec).startswith("cmu:") for spec in specs):
        fields["attribution"] += f"; {CMU_ACKNOWLEDGEMENT}"
    return fields


def data_fields(skeleton: str = "canonical") -> dict:
    """The card's account of what a model reads: rate, skeleton, feature version and layout."""
    return {"fps": FPS, "skeleton": skeleton, "feature_version": FEATURE_VERSION,
            "feature_layout": {k: [s.start, s.stop] for k, s in feature_layout().slices.items()}}


def stylizer_card(path: Path, kind: str, task: str, styles: tuple[str, ...], neutral: str, interface: dict,
                  architecture: dict, training: dict) -> dict:
    """A stylizer's model card (``models/<name>.json``) with the kind's own fields ``interface``
    (state, window, inputs and outputs...); ``metrics`` is filled later by eval/bench."""
    return {"name": path.stem, "kind": kind, "task": task, "styles": list(styles), "neutral_style": neutral,
            **data_fields(), **interface, "architecture": architecture, "training": training, **licence_fields(training),
            "metrics": {}}


def write_card(path: Path, card: dict) -> None:
    """The card beside the ONNX graph at ``path``."""
    path.with_suffix(".json").write_text(json.dumps(card, indent=2) + "\n")


def write_model(path: Path, export: Callable[[Path], None], parity: Callable[[Path, np.ndarray], float],
                card: Callable[[dict], dict], training: dict, probe: np.ndarray | None = None) -> dict:
    """A stylizer's ONNX graph(s) at ``path`` (``export``) and its card beside them (``card`` of the
    ``training`` record), checked against the model contract; returns the card. With a ``probe``
    clip ``(T, F)``, the card records the ``parity`` (largest ONNX vs torch difference) on it."""
    path.parent.mkdir(parents=True, exist_ok=True)
    export(path)
    if probe is not None:
        training = {**training, "onnx_torch_max_abs_diff": parity(path, probe), "parity_probe_frames": len(probe)}
    info = card(training)
    check_card(info, path, info["kind"])
    write_card(path, info)
    return info
