"""The checked-in generated/ packages of the reference scenes, and how to regenerate them.

    python -m codegen.reference_packages          # rewrite generated/
    python -m codegen.reference_packages --check  # compare, exit 1 on any difference

The test suite runs the check: generated/ must be reproduced byte for byte (with the pinned
SymPy and CasADi of pyproject.toml).
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from .package import generate_package, write_package
from .scene import load_scene

ROOT = Path(__file__).resolve().parent.parent
SCENES = ROOT / "scenes"
GENERATED = ROOT / "generated"

#: (scene file, method, quadrature) of every checked-in package
REFERENCE_PACKAGES = (
    ("three_link_gravity.toml", "es", 1),
    ("three_link_mono.toml", "es", 3),
    ("three_link_multi.toml", "es", 3),
    ("three_link_gravity.toml", "vi", 1),
    ("three_link_mono.toml", "vi", 1),
    ("three_link_multi.toml", "vi", 1),
    ("three_link_gravity.toml", "midpoint", 1),
    ("three_link_mono.toml", "midpoint", 1),
    ("three_link_multi.toml", "midpoint", 1),
    ("four_link_actuated.toml", "es", 3),
)


def reference_package(scene_file: str, method: str, quadrature: int):
    return generate_package(load_scene(SCENES / scene_file), method, quadrature)


def differences(package, directory: Path) -> list[str]:
    """Files that differ between `package` and what is on disk in `directory`."""
    on_disk = {p.name for p in directory.iterdir()} if directory.is_dir() else set()
    problems = [f"{directory.name}/{name}: not generated any more"
                for name in sorted(on_disk - set(package.files))]
    for name, text in package.files.items():
        path = directory / name
        if not path.is_file():
            problems.append(f"{directory.name}/{name}: missing")
        elif path.read_bytes() != text.encode():
            problems.append(f"{directory.name}/{name}: differs")
    return problems


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--check", action="store_true", help="compare instead of writing")
    args = parser.parse_args(argv)
    problems = []
    for scene_file, method, quadrature in REFERENCE_PACKAGES:
        package = reference_package(scene_file, method, quadrature)
        directory = GENERATED / package.prefix
        if args.check:
            problems += differences(package, directory)
        else:
            write_package(package, directory)
            print(f"wrote {directory.relative_to(ROOT)}")
    for problem in problems:
        print(problem, file=sys.stderr)
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main())
