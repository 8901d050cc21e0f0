"""The checked-in generated/ packages of the reference scenes, and how to regenerate them.

    python -m chaingen.studies.reference_packages           # rewrite ./generated/
    python -m chaingen.studies.reference_packages --check   # compare, exit 1 on any difference

Run it from the checkout's root (or give --out). The test suite runs the check: generated/ must
be reproduced byte for byte (with the pinned SymPy and CasADi of pyproject.toml).
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from ..generate.package import GeneratedPackage, generate_package, write_package
from ..scene import load_reference_scene

#: (reference scene, method, quadrature) of every checked-in package
REFERENCE_PACKAGES = (
    ("three_link_gravity", "es", 1),
    ("three_link_mono", "es", 3),
    ("three_link_multi", "es", 3),
    ("three_link_gravity", "vi", 1),
    ("three_link_mono", "vi", 1),
    ("three_link_multi", "vi", 1),
    ("three_link_gravity", "midpoint", 1),
    ("three_link_mono", "midpoint", 1),
    ("three_link_multi", "midpoint", 1),
    ("four_link_actuated", "es", 3),
)


def reference_package(scene: str, method: str, quadrature: int) -> GeneratedPackage:
    return generate_package(load_reference_scene(scene), method, quadrature)


def differences(package: GeneratedPackage, directory: Path) -> list[str]:
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
    parser = argparse.ArgumentParser(prog="python -m chaingen.studies.reference_packages",
                                     description=__doc__.splitlines()[0])
    parser.add_argument("--check", action="store_true", help="compare instead of writing")
    parser.add_argument("--out", type=Path, default=Path("generated"),
                        help="the packages' directory (default: ./generated)")
    args = parser.parse_args(argv)
    problems = []
    for scene, method, quadrature in REFERENCE_PACKAGES:
        package = reference_package(scene, method, quadrature)
        directory = args.out / package.prefix
        if args.check:
            problems += differences(package, directory)
        else:
            write_package(package, directory)
            print(f"wrote {directory}")
    for problem in problems:
        print(problem, file=sys.stderr)
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main())
