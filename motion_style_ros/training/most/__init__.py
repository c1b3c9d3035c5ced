"""The MoST stylizer (Kim et al. 2024): its training (:mod:`.trainer`) and its export and model
card (:mod:`.export`). ``motion-style train most`` runs :func:`train`
(:mod:`.command`: its flags, without torch; the other names load on first use)."""

from motion_style_ros.training.lazy import exports

__all__ = ["Config", "Trainer", "companions", "export_onnx", "export_random_model", "parity", "style_means",
           "style_pairs", "tiny_config", "train", "val_targets", "write_model"]
__getattr__ = exports(__name__, {
    "export": ("companions", "export_onnx", "export_random_model", "parity", "write_model"),
    "trainer": ("Config", "Trainer", "style_means", "style_pairs", "tiny_config", "train", "val_targets"),
})
