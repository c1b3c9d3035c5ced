"""The MoST stylizer (Kim et al. 2024): its training (:mod:`.trainer`) and its export and model
card (:mod:`.export`). ``motion-style train most`` runs :func:`train`."""

from motion_style_ros.training.most.export import (
           companions,
           export_onnx,
           export_random_model,
           parity,
           write_model,
)
from motion_style_ros.training.most.trainer import (
           Config,
           Trainer,
           style_means,
           style_pairs,
           tiny_config,
           train,
           val_targets,
)

__all__ = ["Config", "Trainer", "companions", "export_onnx", "export_random_model", "parity", "style_means",
           "style_pairs", "tiny_config", "train", "val_targets", "write_model"]
