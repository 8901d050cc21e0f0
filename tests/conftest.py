"""Shared fixtures: scenes, and generated solvers built once per session.

Builds go to a per-session cache directory (CHAINGEN_CACHE_DIR), so the tests neither read nor
fill the user's cache, and subprocesses of CLI tests share it.
"""
from __future__ import annotations

import os
from functools import lru_cache
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
REFERENCE_SCENES = ("three_link_gravity", "three_link_mono", "three_link_multi")
OWN_SCENES = ("four_link_antagonist", "five_link_biarticular")


def scene_path(name: str) -> Path:
    """A reference scene (scenes/) or one of the test suite's own (tests/scenes/)."""
    for folder in (ROOT / "scenes", ROOT / "tests" / "scenes"):
        path = folder / f"{name}.toml"
        if path.exists():
            return path
    raise FileNotFoundError(name)


@pytest.fixture(scope="session", autouse=True)
def isolated_build_cache(tmp_path_factory):
    previous = os.environ.get("CHAINGEN_CACHE_DIR")
    os.environ["CHAINGEN_CACHE_DIR"] = str(tmp_path_factory.mktemp("chaingen-cache"))
    yield
    if previous is None:
        os.environ.pop("CHAINGEN_CACHE_DIR", None)
    else:
        os.environ["CHAINGEN_CACHE_DIR"] = previous


@lru_cache(maxsize=None)
def load(name: str):
    from codegen.scene import load_scene
    return load_scene(scene_path(name))


_solvers: dict = {}


def solver_for(name: str, method: str = "es", quadrature: int = 3, *,
               sensitivities: bool = False):
    """The built solver of a scene, generated and compiled once per session.

    Without step sensitivities unless asked: they are the largest generated functions, and
    most tests only step forward.
    """
    key = (name, method, quadrature, sensitivities)
    if key not in _solvers:
        from codegen.simulation import build_solver
        _solvers[key] = build_solver(load(name), method, quadrature, sensitivities=sensitivities)
    return _solvers[key]
