"""docs/extremes.md is written by codegen.extremes: complete, and reproducible by the script."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from codegen.extremes import EDGES

ROOT = Path(__file__).resolve().parent.parent
EDGE_NAMES = ("large step", "stiff springs", "mass and inertia ratio", "zero inertia",
              "chain length", "largest n in two minutes", "long run",
              "COM at the proximal joint", "spring segment reaching zero length",
              "Newton not converging")


def table_rows(text: str) -> list[list[str]]:
    rows = [line.strip("|").split(" | ") for line in text.splitlines()
            if line.startswith("| ") and not line.startswith("| edge")]
    return [[cell.strip() for cell in row] for row in rows]


def check_table(text: str) -> None:
    rows = table_rows(text)
    assert {row[0] for row in rows} == set(EDGE_NAMES)
    for row in rows:
        assert len(row) == 5, row
        assert row[3] in ("works", "stops", "refused"), row
        assert row[4] and "nan" not in row[4].lower().split(), row


def test_the_checked_in_study_covers_every_edge():
    assert len(EDGES) == len(EDGE_NAMES)
    text = (ROOT / "docs" / "extremes.md").read_text()
    assert "Written by `python -m codegen.extremes`" in text and "--quick" not in text
    check_table(text)


@pytest.mark.benchmark
def test_the_study_script_runs(tmp_path):
    """The script itself, in its quick form (the full one takes about 20 minutes)."""
    out = tmp_path / "extremes.md"
    result = subprocess.run([sys.executable, "-m", "codegen.extremes", "--quick", "--out",
                             str(out)], capture_output=True, text=True, cwd=ROOT)
    assert result.returncode == 0, result.stderr
    check_table(out.read_text())
