"""The extremes study (chaingen.studies.extremes): its table, and the script in its quick form."""
from __future__ import annotations

import subprocess
import sys

import pytest

from chaingen.studies.extremes import EDGES, Outcome, markdown

EDGE_NAMES = ("large step", "stiff springs", "adaptive steps", "mass and inertia ratio",
              "hard Newton steps",
              "zero inertia",
              "chain length", "largest n in two minutes", "long run",
              "COM at the proximal joint", "spring segment reaching zero length",
              "Newton not converging")


def table_rows(text: str) -> list[list[str]]:
    rows = [line.strip("|").split(" | ") for line in text.splitlines()
            if line.startswith("| ") and not line.startswith("| edge")]
    return [[cell.strip() for cell in row] for row in rows]


def check_table(text: str, edges=EDGE_NAMES) -> None:
    rows = table_rows(text)
    assert {row[0] for row in rows} == set(edges)
    for row in rows:
        assert len(row) == 5, row
        assert row[3] in ("works", "stops", "refused"), row
        assert row[4] and "nan" not in row[4].lower().split(), row


def test_the_table_has_a_row_per_outcome_and_escapes_bars():
    rows = [Outcome("long run", "es K = 3", "1e6 steps", "works", "error 1e-13 | bounded"),
            Outcome("zero inertia", "vi", "J = 0", "stops", "step 3 failed")]
    text = markdown(rows, quick=True)
    assert "Written by `python -m chaingen.studies.extremes` --quick" in text
    check_table(text, edges=("long run", "zero inertia"))
    assert "error 1e-13 \\| bounded" in text
    assert len(EDGES) == len(EDGE_NAMES)


@pytest.mark.benchmark
def test_the_study_script_runs(tmp_path):
    """The script itself, in its quick form (the full one takes about 20 minutes)."""
    out = tmp_path / "extremes.md"
    result = subprocess.run([sys.executable, "-m", "chaingen.studies.extremes", "--quick",
                             "--out", str(out)], capture_output=True, text=True, cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    check_table(out.read_text())
