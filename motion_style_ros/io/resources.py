"""The shipped rotation statistics (``resources/rotation_stats.json``): what the stream conditioning
(:mod:`motion_style_ros.core.conform`, :mod:`motion_style_ros.core.proportions`) aligns a performer
to. Read here, apart from the dataset indexer, so that the runtime needs no dataset code;
``motion-style data rotation-stats`` recomputes the file from the datasets
(:func:`motion_style_ros.io.datasets.rotation_stats_json`)."""

from __future__ import annotations

import json
from importlib import resources
from pathlib import Path

import numpy as np

ROTATION_STATS_FILE = "resources/rotation_stats.json"  # 6D local-rotation statistics, train split


def rotation_stats_file() -> Path:
    """Where the shipped statistics are (inside the installed package)."""
    return Path(str(resources.files("motion_style_ros") / ROTATION_STATS_FILE))


def rotation_stats() -> dict[str, np.ndarray]:
    """Per-joint 6D local-rotation mean and std, the planted-ankle height and the stride scale of
    the Bandai dataset-2 training takes (shipped; :func:`motion_style_ros.core.conform.statistics`)."""
    data = json.loads(rotation_stats_file().read_text(encoding="utf-8"))
    return {"names": np.array(data["names"]), "mean": np.array(data["mean"]), "std": np.array(data["std"]),
            "ankle_height": float(data["ankle_height"]), "scale_reference": float(data["scale_reference"])}
