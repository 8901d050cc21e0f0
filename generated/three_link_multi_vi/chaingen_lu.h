/* Dense LU factorisation with partial pivoting, for the Newton systems of chaingen solvers.
 *
 * Header-only and static: every generated package includes its own copy, nothing is exported.
 * Matrices are column-major (a[i + j*n] is row i, column j), as CasADi writes dense outputs.
 */
#ifndef CHAINGEN_LU_H
#define CHAINGEN_LU_H

#include <math.h>

/* Column k's pivot: the entry of largest magnitude on or below the diagonal, its row swapped
 * with row k across the whole matrix; the diagonal replaced by its reciprocal and the column
 * below it scaled by that. Returns 0, or 1 if the column has no usable pivot (zero or not
 * finite). */
static int chaingen_lu_pivot(int n, double *a, int *pivot, int k)
{
    int i, j, p = k;
    double largest = fabs(a[k + k * n]), reciprocal;
    for (i = k + 1; i < n; ++i) {
        double magnitude = fabs(a[i + k * n]);
        if (magnitude > largest) {
            largest = magnitude;
            p = i;
        }
    }
    pivot[k] = p;
    if (!(largest > 0.0) || !isfinite(largest)) {
        return 1;
    }
    if (p != k) {
        for (j = 0; j < n; ++j) {
            double swap = a[k + j * n];
            a[k + j * n] = a[p + j * n];
            a[p + j * n] = swap;
        }
    }
    reciprocal = 1.0 / a[k + k * n];
    a[k + k * n] = reciprocal;
    for (i = k + 1; i < n; ++i) {
        a[i + k * n] *= reciprocal;
    }
    return 0;
}

/* The trailing update of four adjacent columns c, c + n, c + 2n, c + 3n by the pivots k and
 * k + 1 (multipliers l0 and l1): row k + 1 by pivot k, the rows below by both. Each entry is
 * loaded and stored once for the two pivots (the update is bound by loads and stores at these
 * sizes), with the same operations in the same order as one pivot at a time, so the factors are
 * bitwise those of the textbook loop. A function of its own so that restrict tells the
 * compiler the columns do not overlap, and it vectorises the loop without run-time checks. */
static void chaingen_lu_update4(int n, int k, const double *restrict l0,
                                const double *restrict l1, double *restrict c)
{
    int i;
    double *restrict c0 = c, *restrict c1 = c + n, *restrict c2 = c + 2 * n,
           *restrict c3 = c + 3 * n;
    const double u0 = c0[k], u1 = c1[k], u2 = c2[k], u3 = c3[k];
    const double v0 = c0[k + 1] - l0[k + 1] * u0, v1 = c1[k + 1] - l0[k + 1] * u1,
                 v2 = c2[k + 1] - l0[k + 1] * u2, v3 = c3[k + 1] - l0[k + 1] * u3;
    c0[k + 1] = v0;
    c1[k + 1] = v1;
    c2[k + 1] = v2;
    c3[k + 1] = v3;
    for (i = k + 2; i < n; ++i) {
        const double p = l0[i], q = l1[i];
        c0[i] = (c0[i] - p * u0) - q * v0;
        c1[i] = (c1[i] - p * u1) - q * v1;
        c2[i] = (c2[i] - p * u2) - q * v2;
        c3[i] = (c3[i] - p * u3) - q * v3;
    }
}

/* Factorise a in place into L (unit lower, below the diagonal) and U (on and above it), with
 * row swaps in pivot. The diagonal holds the reciprocals 1 / u_kk, so that a solve multiplies
 * instead of dividing (a chain of divisions is most of a small solve's latency). Right-looking,
 * two pivots at a time: column k + 1 is updated by pivot k and pivoted, then the columns right
 * of both are updated by both at once (chaingen_lu_update4).
 * Returns 0, or k + 1 if column k has no usable pivot (zero or not finite). */
static int chaingen_lu_factor(int n, double *a, int *pivot)
{
    int i, j, k;
    for (k = 0; k < n; k += 2) {
        const double *l0 = a + k * n, *l1 = l0 + n;
        if (chaingen_lu_pivot(n, a, pivot, k)) {
            return k + 1;
        }
        if (k + 1 == n) {
            break;
        }
        {
            double *c = a + (k + 1) * n;
            const double u = c[k];
            for (i = k + 1; i < n; ++i) {
                c[i] -= l0[i] * u;
            }
        }
        if (chaingen_lu_pivot(n, a, pivot, k + 1)) {
            return k + 2;
        }
        for (j = k + 2; j + 3 < n; j += 4) {
            chaingen_lu_update4(n, k, l0, l1, a + j * n);
        }
        for (; j < n; ++j) {
            double *c = a + j * n;
            const double u = c[k], v = c[k + 1] - l0[k + 1] * u;
            c[k + 1] = v;
            for (i = k + 2; i < n; ++i) {
                c[i] = (c[i] - l0[i] * u) - l1[i] * v;
            }
        }
    }
    return 0;
}

/* Solve (LU) x = b in place of b, with the factors and pivots of chaingen_lu_factor. */
static void chaingen_lu_solve(int n, const double *lu, const int *pivot, double *b)
{
    int i, j;
    for (i = 0; i < n; ++i) {
        if (pivot[i] != i) {
            double swap = b[i];
            b[i] = b[pivot[i]];
            b[pivot[i]] = swap;
        }
    }
    for (j = 0; j < n; ++j) {
        double bj = b[j];
        for (i = j + 1; i < n; ++i) {
            b[i] -= lu[i + j * n] * bj;
        }
    }
    for (j = n - 1; j >= 0; --j) {
        double bj = b[j] * lu[j + j * n];
        b[j] = bj;
        for (i = 0; i < j; ++i) {
            b[i] -= lu[i + j * n] * bj;
        }
    }
}

#endif /* CHAINGEN_LU_H */
