"""The sequence adversarial autoencoder (ESANN 2018 seed: plain SAAE, Model1, Model2): its training
(:mod:`.trainer`) and its export and model card (:mod:`.export`). ``motion-style train saae`` runs
:func:`train`."""

from motion_style_ros.training.saae.export import (
    companions,
    export_onnx,
    export_random_model,
    model_name,
    parity,
    write_model,
)
from motion_style_ros.training.saae.trainer import Config, Trainer, tiny_config, train

__all__ = ["Config", "Trainer", "companions", "export_onnx", "export_random_model", "model_name", "parity",
           "tiny_config", "train", "write_model"]
