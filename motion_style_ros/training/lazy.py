"""A trainer package's names loaded on first use, so that its torch-free ``command`` module (what
``motion-style``'s parser reads on every call) imports without torch."""

from __future__ import annotations

import importlib
from collections.abc import Callable


def exports(package: str, names: dict[str, tuple[str, ...]]) -> Callable[[str], object]:
    """A module ``__getattr__`` for ``package``: each name of ``names[submodule]`` comes from
    ``package.submodule`` when first asked for."""
    where = {name: module for module, listed in names.items() for name in listed}

    def __getattr__(name: str) -> object:
        if name not in where:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        return getattr(importlib.import_module(f"{package}.{where[name]}"), name)

    return __getattr__
