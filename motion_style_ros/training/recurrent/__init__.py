"""Style-ERD, the recurrent online stylizer: its training (:mod:`.trainer`) and its export and
model card (:mod:`.export`). ``motion-style train recurrent`` runs :func:`train`."""

from motion_style_ros.training.recurrent.export import card, export_onnx, export_random_model, parity, write_model
from motion_style_ros.training.recurrent.trainer import (
    NAME,
    Config,
    Trainer,
    content_network,
    load_generator,
    tiny_config,
    train,
)

__all__ = ["NAME", "Config", "Trainer", "card", "content_network", "export_onnx", "export_random_model",
           "load_generator", "parity", "tiny_config", "train", "write_model"]
