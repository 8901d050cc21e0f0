"""The dense LU every package carries (runtime/c/chaingen_lu.h), compiled on its own: the
factors of random matrices of every size through 41 (both parities of the two-pivot loop, the
four-column update and its remainder) solve the system as numpy does, the factors are those of
one pivot at a time, and a column without a usable pivot is reported by its number."""
from __future__ import annotations

import importlib.resources
import subprocess

import numpy as np
import pytest

from chaingen.runtime.build import STRICT_FLAGS, compiler

pytestmark = pytest.mark.compile

#: Reads n, then the column-major matrix and a right-hand side; prints the status, the factors,
#: the pivots and the solution.
PROGRAM = r"""
#include <stdio.h>
#include <stdlib.h>
#include "chaingen_lu.h"
int main(void)
{
    int n, i, status;
    double *a, *b;
    int *pivot;
    if (scanf("%d", &n) != 1) {
        return 3;
    }
    a = malloc(sizeof *a * (size_t)(n * n));
    b = malloc(sizeof *b * (size_t)n);
    pivot = malloc(sizeof *pivot * (size_t)n);
    for (i = 0; i < n * n; ++i) {
        if (scanf("%lf", &a[i]) != 1) {
            return 3;
        }
    }
    for (i = 0; i < n; ++i) {
        if (scanf("%lf", &b[i]) != 1) {
            return 3;
        }
    }
    status = chaingen_lu_factor(n, a, pivot);
    printf("%d\n", status);
    if (status == 0) {
        chaingen_lu_solve(n, a, pivot, b);
        for (i = 0; i < n * n; ++i) {
            printf("%.17g ", a[i]);
        }
        printf("\n");
        for (i = 0; i < n; ++i) {
            printf("%d ", pivot[i]);
        }
        printf("\n");
        for (i = 0; i < n; ++i) {
            printf("%.17g ", b[i]);
        }
        printf("\n");
    }
    free(a);
    free(b);
    free(pivot);
    return 0;
}
"""


@pytest.fixture(scope="module")
def program(tmp_path_factory):
    directory = tmp_path_factory.mktemp("lu")
    header = importlib.resources.files("chaingen.runtime").joinpath("c", "chaingen_lu.h")
    (directory / "chaingen_lu.h").write_text(header.read_text())
    (directory / "main.c").write_text(PROGRAM)
    subprocess.run([compiler(), *STRICT_FLAGS, "-O3", "-I.", "main.c", "-o", "lu", "-lm"],
                   cwd=directory, check=True)
    return directory / "lu"


def factor(program, a: np.ndarray, b: np.ndarray):
    """(status, factors column-major, pivots, solution) of the compiled LU."""
    n = len(b)
    text = " ".join([str(n), *map(repr, a.flatten(order="F").tolist()),
                     *map(repr, b.tolist())])
    lines = subprocess.run([str(program)], input=text, capture_output=True, text=True,
                           check=True).stdout.split("\n")
    status = int(lines[0])
    if status:
        return status, None, None, None
    factors = np.array(lines[1].split(), dtype=float).reshape((n, n), order="F")
    return (status, factors, np.array(lines[2].split(), dtype=int),
            np.array(lines[3].split(), dtype=float))


def textbook(a: np.ndarray):
    """Right-looking LU with partial pivoting, one pivot at a time, in the header's layout
    (reciprocal diagonal): the arithmetic the two-pivot loop must reproduce bit for bit."""
    a = a.copy()
    n = len(a)
    pivot = np.empty(n, dtype=int)
    for k in range(n):
        p = k + int(np.argmax(np.abs(a[k:, k])))
        pivot[k] = p
        a[[k, p], :] = a[[p, k], :]
        a[k, k] = 1.0 / a[k, k]
        a[k + 1:, k] *= a[k, k]
        for j in range(k + 1, n):
            a[k + 1:, j] = a[k + 1:, j] - a[k + 1:, k] * a[k, j]
    return a, pivot


@pytest.mark.parametrize("n", range(1, 42))
def test_factors_solve_and_equal_one_pivot_at_a_time(program, n):
    rng = np.random.default_rng(n)
    a = rng.standard_normal((n, n))
    b = rng.standard_normal(n)
    status, factors, pivot, x = factor(program, a, b)
    assert status == 0
    np.testing.assert_allclose(x, np.linalg.solve(a, b), rtol=1e-9,
                               atol=1e-9 * np.abs(x).max())
    expected, expected_pivot = textbook(a)
    np.testing.assert_array_equal(pivot, expected_pivot)
    np.testing.assert_array_equal(factors, expected)       # bitwise


@pytest.mark.parametrize("n, column", [(1, 0), (2, 1), (5, 0), (6, 3), (7, 6), (12, 5)])
def test_column_without_pivot_is_reported(program, n, column):
    rng = np.random.default_rng(100 + n)
    a = rng.standard_normal((n, n))
    a[:, column] = 0.0
    assert factor(program, a, np.ones(n))[0] == column + 1
    a[:, column] = np.nan                  # columns left of it are not touched by it
    assert factor(program, a, np.ones(n))[0] == column + 1
