/* Dense LU factorisation with partial pivoting, for the Newton systems of chaingen solvers.
 *
 * Header-only and static: every generated package includes its own copy, nothing is exported.
 * Matrices are column-major (a[i + j*n] is row i, column j), as CasADi writes dense outputs.
 */
#ifndef CHAINGEN_LU_H
#define CHAINGEN_LU_H

#include <math.h>

/* Factorise a in place into L (unit lower, below the diagonal) and U (on and above it), with
 * row swaps in pivot. The diagonal holds the reciprocals 1 / u_kk, so that a solve multiplies
 * instead of dividing (a chain of divisions is most of a small solve's latency).
 * Returns 0, or k + 1 if column k has no usable pivot (zero or not finite). */
static int chaingen_lu_factor(int n, double *a, int *pivot)
{
    int i, j, k;
    for (k = 0; k < n; ++k) {
        int p = k;
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
            return k + 1;
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
        /* The trailing update, four columns at a time: each entry of column k is loaded once
         * for the four (the update is bound by loads at these sizes). */
        for (j = k + 1; j + 3 < n; j += 4) {
            const double *l = a + k * n;
            double *c0 = a + j * n, *c1 = c0 + n, *c2 = c1 + n, *c3 = c2 + n;
            const double u0 = c0[k], u1 = c1[k], u2 = c2[k], u3 = c3[k];
            for (i = k + 1; i < n; ++i) {
                const double li = l[i];
                c0[i] -= li * u0;
                c1[i] -= li * u1;
                c2[i] -= li * u2;
                c3[i] -= li * u3;
            }
        }
        for (; j < n; ++j) {
            double ukj = a[k + j * n];
            for (i = k + 1; i < n; ++i) {
                a[i + j * n] -= a[i + k * n] * ukj;
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
