"""The windowed ST-GCN stylizer (Park et al. 2021): its training (:mod:`.trainer`) and its export
and model card (:mod:`.export`). ``motion-style train stgcn`` runs :func:`train`."""

from motion_style_ros.training.stgcn.export import companions, export_onnx, export_random_model, parity, write_model
from motion_style_ros.training.stgcn.trainer import Config, Trainer, tiny_config, train

__all__ = ["Config", "Trainer", "companions", "export_onnx", "export_random_model", "parity", "tiny_config",
           "train", "write_model"]
