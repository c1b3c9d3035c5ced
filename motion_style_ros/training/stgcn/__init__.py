"""The windowed ST-GCN stylizer (Park et al. 2021): its training (:mod:`.trainer`) and its export
and model card (:mod:`.export`). ``motion-style train stgcn`` runs :func:`train`."""

from motion_style_ros.training.stgcn.export import (
    card,
    companions,
    export_onnx,
    export_random_model,
    parity,
    write_model,
)
from motion_style_ros.training.stgcn.trainer import NAME, Config, Trainer, tiny_config, train

__all__ = ["NAME", "Config", "Trainer", "card", "companions", "export_onnx", "export_random_model", "parity",
           "tiny_config", "train", "write_model"]
