"""Style-ERD, the recurrent online stylizer: its training (:mod:`.trainer`) and its export and
model card (:mod:`.export`). ``motion-style train recurrent`` runs :func:`train`
(:mod:`.command`: its flags, without torch; the other names load on first use)."""

from motion_style_ros.training.lazy import exports

__all__ = ["Config", "Trainer", "export_onnx", "export_random_model", "load_generator", "tiny_config", "train"]
__getattr__ = exports(__name__, {
    "export": ("export_onnx", "export_random_model"),
    "trainer": ("Config", "Trainer", "load_generator", "tiny_config", "train"),
})
