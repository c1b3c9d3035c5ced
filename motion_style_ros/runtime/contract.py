"""The model contract: what every ONNX model this package runs takes and gives, and what its card
must say. Torch-free, so that the export code (training) and the sessions (runtime) read the same
names and the same card check instead of writing them out each."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from motion_style_ros.core.features import FEATURE_VERSION
from motion_style_ros.errors import MotionStyleError


@dataclass(frozen=True)
class Contract:
    """One model's ONNX input and output names, in export order."""

    inputs: tuple[str, ...]
    outputs: tuple[str, ...]

    def check(self, input_names: list[str], path: Path, what: str) -> None:
        """A one-line error when the model at ``path`` lacks any of the inputs (``what``: the kind
        of model it should be, for the message)."""
        missing = set(self.inputs) - set(input_names)
        if missing:
            raise MotionStyleError(f"{path}: not a {what} (no inputs {', '.join(sorted(missing))})")


# Style-ERD: one frame's features, style weights, alpha, the LSTM state and a reset flag in; the
# stylized [root | rot6d] frame and the next state out.
RECURRENT = Contract(("features", "style", "alpha", "state", "reset"), ("output", "state_out"))
# The ST-GCN generator: a window of features and a style code in, the stylized window out.
WINDOWED = Contract(("features", "code"), ("output",))
# The generator's companions: latent noise and a one-hot style to a code; a clip to every style's
# code and the style logits.
MAPPING = Contract(("z", "style"), ("code",))
STYLE_ENCODER = Contract(("features",), ("codes", "logits"))
# An evaluation judge: a clip's features to class logits and an embedding.
JUDGE = Contract(("features",), ("logits", "embedding"))
# The sequence adversarial autoencoder (ESANN 2018 seed): the encoder (a window to its content
# code), the decoder (content code, style input, each frame's position in the window to the
# [root | rot6d] frames) and Model2's style encoder (a window to its style code and style logits).
SAAE_ENCODER = Contract(("features",), ("content",))
SAAE_DECODER = Contract(("content", "style", "position"), ("output",))
SAAE_STYLE_ENCODER = Contract(("features",), ("style_code", "logits"))
# MoST: the streamed step (a window, the reference's body-part style feature S and mean
# content feature C, alpha from the window's own style to the reference's) and the style side of
# its encoder, run once per reference clip.
MOST = Contract(("features", "style", "pooled", "alpha"), ("output",))
MOST_STYLE = Contract(("features",), ("style", "pooled"))

CARD_KEYS = ("kind", "styles", "fps", "feature_version")  # every stylizer's card
KIND_KEYS: dict[str, tuple[str, ...]] = {  # and each kind's own
    "recurrent": ("state_size",),
    "stgcn": ("window", "latent_dim", "style_dim", "files"),
    "saae": ("window", "variant", "content_dim", "style_width", "style_inputs", "files"),
    "most": ("window", "parts", "feature_dim", "files"),
}


def check_card(card: dict, path: Path, kind: str) -> None:
    """A one-line error unless the card describes a ``kind`` stylizer (:data:`KIND_KEYS`) on the
    canonical skeleton and the features this package computes."""
    missing = [k for k in (*CARD_KEYS, *KIND_KEYS[kind]) if k not in card]
    if missing:
        raise MotionStyleError(f"{path.with_suffix('.json')}: model card lacks {', '.join(missing)}")
    if card["kind"] != kind:
        raise MotionStyleError(f"{path}: a {card['kind']!r} model, not a {kind} stylizer")
    if card.get("skeleton", "canonical") != "canonical":
        raise MotionStyleError(
            f"{path}: made for skeleton {card['skeleton']!r}; the session streams the canonical one"
        )
    if card["feature_version"] != FEATURE_VERSION:
        raise MotionStyleError(
            f"{path}: made for feature version {card['feature_version']}; this package computes "
            f"version {FEATURE_VERSION} (retrain or update the package)"
        )
