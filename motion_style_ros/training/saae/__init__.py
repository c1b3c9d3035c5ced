"""The sequence adversarial autoencoder (ESANN 2018 seed: plain SAAE, Model1, Model2): its training
(:mod:`.trainer`) and its export and model card (:mod:`.export`). ``motion-style train saae`` runs
:func:`train` (:mod:`.command`: its flags, without torch; the other names load on first use)."""

from motion_style_ros.training.lazy import exports

__all__ = ["Config", "Trainer", "companions", "export_onnx", "export_random_model", "model_name", "parity",
           "tiny_config", "train", "write_model"]
__getattr__ = exports(__name__, {
    "export": ("companions", "export_onnx", "export_random_model", "model_name", "parity", "write_model"),
    "trainer": ("Config", "Trainer", "tiny_config", "train"),
})
