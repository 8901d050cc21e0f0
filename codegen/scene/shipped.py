"""The scenes shipped with chaingen (scenes/ in the source tree, installed as the package
data chaingen.scenes), named on the command line by their bare name."""
from __future__ import annotations

import importlib.resources
import os
from pathlib import Path

#: The package that holds the scenes shipped with chaingen (scenes/ in the source tree).
SHIPPED_SCENES = "chaingen.scenes"


def scene_file(path: str | os.PathLike[str]) -> Path:
    """The file a scene argument names: `path` itself, or, where no such file exists and
    `path` is a bare name (no directory), the shipped scene of that name (with or without
    .toml) from the installed package data, so `chaingen simulate three_link_mono` works from
    any directory and after any kind of install."""
    text = os.fspath(path)
    path = Path(text)
    if os.path.lexists(path) or os.sep in text or not path.name:
        return path
    name = path.name if path.suffix == ".toml" else f"{path.name}.toml"
    try:
        shipped = importlib.resources.files(SHIPPED_SCENES) / name
    except ModuleNotFoundError:
        return path
    try:
        if isinstance(shipped, Path) and shipped.is_file():
            return shipped
    except OSError:     # a name no file can have (too long): the argument, refused as given
        pass
    return path
