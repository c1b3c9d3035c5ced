"""Style-ERD, the recurrent online stylizer: its training (:mod:`.trainer`) and its export and
model card (:mod:`.export`). ``motion-style train recurrent`` runs :func:`train`."""

from motion_style_ros.training.recurrent.export import export_onnx, export_random_model
from motion_style_ros.training.recurrent.trainer import Config, Trainer, load_generator, tiny_config, train

__all__ = ["Config", "Trainer", "export_onnx", "export_random_model", "load_generator", "tiny_config", "train"]
