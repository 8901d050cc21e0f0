/* es's Newton systems solved by the factors of their Jacobian, in O(n^2) (docs/model.md,
 * section 18).
 *
 * Header-only and static, like chaingen_lu.h: every package that uses it includes its own copy,
 * nothing is exported, nothing is allocated (the caller's workspace holds every array).
 *
 * The Jacobian of es's residual F = (M dv + dt m g + B^T h(w, mu), c(w)), w = B dv, is
 *
 *     J = [ M + B^T H B   B^T G_mu ]      H = dh/dw (sparse, banded), G_mu = dh/dmu and
 *         [ G_c B         0        ]      G_c = dc/dw (one 2-vector per link each),
 *
 * with M the COM masses and B the constant map from q to the arms d_k = x_k - X_k, whose inverse
 * P is the joint recursion X_1 = 0, x_k = X_k + d_k, X_{k+1} = X_k + A_k d_k. In the arms'
 * coordinates (dv = P dw) the system is
 *
 *     (P^T M P + H) dw + G_mu dmu = P^T r1,      G_c dw = r2,
 *
 * local but for P^T M P, the chain's mass matrix in the arms, which has the closed form below.
 * Link k's constraint row fixes dw_k along g_k = G_c,k: dw_k = r2_k g_k / |g_k|^2 + theta_k t_k
 * with t_k = S g_k / |g_k|; projecting link k's momentum rows on t'_k = S G_mu,k / |G_mu,k|
 * removes dmu_k. What is left is n x n, S theta = rhs with S_ij = t'_i . (P^T M P + H)_ij t_j,
 * formed in O(n^2) and factorised by dense LU with partial pivoting (chaingen_lu.h); dmu_k is
 * then the G_mu,k component of link k's momentum rows.
 *
 * Vectors in q's order are (x_1..x_n, y_1..y_n) as F's and z's; vectors on the arms are link by
 * link, (x, y) pairs. A_k is row-major (A[4k] A[4k+1]; A[4k+2] A[4k+3]).
 */
#ifndef CHAINGEN_ARM_SOLVE_H
#define CHAINGEN_ARM_SOLVE_H

#include <math.h>

#include "chaingen_lu.h"

typedef struct {
    int n;                  /* links */
    int nh;                 /* structural nonzeros of H */
    const int *h_row;       /* their rows and columns, on the arms (2k + component) */
    const int *h_col;
    const double *h;        /* H's nonzeros, then G_mu (2n), G_c (2n), m (n), A (4n) */
    double *derived;        /* 15n: t, t', r2's direction g / |g|^2, U, U', C, C' (2n each),
                             * then the masses outboard of each link (n) */
    double *reduced;        /* n x n: S, then its LU factors */
    int *pivot;             /* n */
    double *scratch;        /* 6n */
} chaingen_arm_system;

#define CHAINGEN_ARM_GMU(s) ((s)->h + (s)->nh)
#define CHAINGEN_ARM_GC(s) ((s)->h + (s)->nh + 2 * (s)->n)
#define CHAINGEN_ARM_MASS(s) ((s)->h + (s)->nh + 4 * (s)->n)
#define CHAINGEN_ARM_MAP(s) ((s)->h + (s)->nh + 5 * (s)->n)

/* x = P d (arms to q's order). */
static void chaingen_arm_to_q(const chaingen_arm_system *s, const double *d, double *x)
{
    const double *A = CHAINGEN_ARM_MAP(s);
    double X0 = 0.0, X1 = 0.0;
    int k;
    for (k = 0; k < s->n; ++k) {
        const double *a = A + 4 * k, d0 = d[2 * k], d1 = d[2 * k + 1];
        x[k] = X0 + d0;
        x[s->n + k] = X1 + d1;
        X0 += a[0] * d0 + a[1] * d1;
        X1 += a[2] * d0 + a[3] * d1;
    }
}

/* d = P^T y (q's order to the arms): d_k = y_k + A_k^T (y_{k+1} + ... + y_n). */
static void chaingen_arm_from_q(const chaingen_arm_system *s, const double *y, double *d)
{
    const double *A = CHAINGEN_ARM_MAP(s);
    double tail0 = 0.0, tail1 = 0.0;
    int k;
    for (k = s->n - 1; k >= 0; --k) {
        const double *a = A + 4 * k;
        d[2 * k] = y[k] + a[0] * tail0 + a[2] * tail1;
        d[2 * k + 1] = y[s->n + k] + a[1] * tail0 + a[3] * tail1;
        tail0 += y[k];
        tail1 += y[s->n + k];
    }
}

/* out = (P^T M P + H) d on the arms; uses scratch[0, 2n). */
static void chaingen_arm_apply(const chaingen_arm_system *s, const double *d, double *out)
{
    const double *m = CHAINGEN_ARM_MASS(s);
    double *x = s->scratch;
    int k;
    chaingen_arm_to_q(s, d, x);
    for (k = 0; k < s->n; ++k) {
        x[k] *= m[k];
        x[s->n + k] *= m[k];
    }
    chaingen_arm_from_q(s, x, out);
    for (k = 0; k < s->nh; ++k) {
        out[s->h_row[k]] += s->h[k] * d[s->h_col[k]];
    }
}

/* Form S and factorise it. Returns 0, or k + 1 if link k's G_c or G_mu vanishes, or n + k + 1
 * if S has no usable pivot in column k (chaingen_lu_factor). */
static int chaingen_arm_factor(const chaingen_arm_system *s)
{
    const int n = s->n;
    const double *gmu = CHAINGEN_ARM_GMU(s), *gc = CHAINGEN_ARM_GC(s);
    const double *m = CHAINGEN_ARM_MASS(s), *A = CHAINGEN_ARM_MAP(s);
    double *t = s->derived, *tp = t + 2 * n, *normal = tp + 2 * n, *U = normal + 2 * n;
    double *Up = U + 2 * n, *C = Up + 2 * n, *Cp = C + 2 * n, *outboard = Cp + 2 * n;
    double *S = s->reduced, mass = 0.0;
    int i, j, k, status;
    for (k = n - 1; k >= 0; --k) {
        const double *a = A + 4 * k;
        const double g2 = gc[2 * k] * gc[2 * k] + gc[2 * k + 1] * gc[2 * k + 1];
        const double gm = sqrt(gmu[2 * k] * gmu[2 * k] + gmu[2 * k + 1] * gmu[2 * k + 1]);
        const double g = sqrt(g2);
        if (!(g > 0.0) || !(gm > 0.0) || !isfinite(g2) || !isfinite(gm)) {
            return k + 1;
        }
        outboard[k] = mass;
        mass += m[k];
        t[2 * k] = -gc[2 * k + 1] / g;
        t[2 * k + 1] = gc[2 * k] / g;
        tp[2 * k] = -gmu[2 * k + 1] / gm;
        tp[2 * k + 1] = gmu[2 * k] / gm;
        normal[2 * k] = gc[2 * k] / g2;
        normal[2 * k + 1] = gc[2 * k + 1] / g2;
        U[2 * k] = a[0] * t[2 * k] + a[1] * t[2 * k + 1];
        U[2 * k + 1] = a[2] * t[2 * k] + a[3] * t[2 * k + 1];
        Up[2 * k] = a[0] * tp[2 * k] + a[1] * tp[2 * k + 1];
        Up[2 * k + 1] = a[2] * tp[2 * k] + a[3] * tp[2 * k + 1];
        C[2 * k] = m[k] * t[2 * k] + outboard[k] * U[2 * k];
        C[2 * k + 1] = m[k] * t[2 * k + 1] + outboard[k] * U[2 * k + 1];
        Cp[2 * k] = m[k] * tp[2 * k] + outboard[k] * Up[2 * k];
        Cp[2 * k + 1] = m[k] * tp[2 * k + 1] + outboard[k] * Up[2 * k + 1];
    }
    /* P^T M P between arms i and j: sum over the links l >= max(i, j) of m_l (dx_l/dd_i)^T
     * dx_l/dd_j, with dx_l/dd_k = I for l = k and A_k for l > k. */
    for (j = 0; j < n; ++j) {
        for (i = 0; i < j; ++i) {
            S[i + j * n] = Up[2 * i] * C[2 * j] + Up[2 * i + 1] * C[2 * j + 1];
        }
        S[j + j * n] = m[j] * (tp[2 * j] * t[2 * j] + tp[2 * j + 1] * t[2 * j + 1])
                       + outboard[j] * (Up[2 * j] * U[2 * j] + Up[2 * j + 1] * U[2 * j + 1]);
        for (i = j + 1; i < n; ++i) {
            S[i + j * n] = Cp[2 * i] * U[2 * j] + Cp[2 * i + 1] * U[2 * j + 1];
        }
    }
    for (k = 0; k < s->nh; ++k) {
        const int r = s->h_row[k], c = s->h_col[k];
        S[r / 2 + (c / 2) * n] += tp[r] * s->h[k] * t[c];
    }
    status = chaingen_lu_factor(n, S, s->pivot);
    return status ? n + status : 0;
}

/* Solve J z = b in place of b (b: r1 in q's order, then r2; z: dv in q's order, then dmu),
 * with the factors of chaingen_arm_factor. Uses scratch. */
static void chaingen_arm_solve(const chaingen_arm_system *s, double *b)
{
    const int n = s->n;
    const double *gmu = CHAINGEN_ARM_GMU(s);
    const double *t = s->derived, *tp = t + 2 * n, *normal = tp + 2 * n;
    double *target = s->scratch + 2 * n, *dw = target + 2 * n, *theta = s->scratch;
    int k;
    chaingen_arm_from_q(s, b, target);
    for (k = 0; k < n; ++k) {
        dw[2 * k] = b[2 * n + k] * normal[2 * k];
        dw[2 * k + 1] = b[2 * n + k] * normal[2 * k + 1];
    }
    chaingen_arm_apply(s, dw, b);   /* b is free now: A dw_0 */
    for (k = 0; k < n; ++k) {
        theta[k] = tp[2 * k] * (target[2 * k] - b[2 * k])
                   + tp[2 * k + 1] * (target[2 * k + 1] - b[2 * k + 1]);
    }
    chaingen_lu_solve(n, s->reduced, s->pivot, theta);
    for (k = 0; k < n; ++k) {
        dw[2 * k] += theta[k] * t[2 * k];
        dw[2 * k + 1] += theta[k] * t[2 * k + 1];
    }
    chaingen_arm_apply(s, dw, b);
    for (k = 0; k < n; ++k) {
        const double g2 = gmu[2 * k] * gmu[2 * k] + gmu[2 * k + 1] * gmu[2 * k + 1];
        b[2 * n + k] = (gmu[2 * k] * (target[2 * k] - b[2 * k])
                        + gmu[2 * k + 1] * (target[2 * k + 1] - b[2 * k + 1])) / g2;
    }
    chaingen_arm_to_q(s, dw, b);
}

/* The dense Jacobian J (3n x 3n, column-major) from the factors, O(n^2): column by column, the
 * arms' w = B e by the recursion w_k = x_k - X_k, X_{k+1} = X_k + A_k w_k, then
 * M e + B^T (H w) and G_c w (a dv column), or B^T G_mu e and 0 (a dmu column); B^T y by the
 * sweep g_k = y_k + A_k^T L_{k+1}, L_k = -y_k + (I - A_k)^T L_{k+1}. For verification
 * (residual_jacobian): the Newton loop never forms J. Uses scratch[0, 4n). */
static void chaingen_arm_jacobian(const chaingen_arm_system *s, double *J)
{
    const int n = s->n, nz = 3 * n;
    const double *gmu = CHAINGEN_ARM_GMU(s), *gc = CHAINGEN_ARM_GC(s);
    const double *m = CHAINGEN_ARM_MASS(s), *A = CHAINGEN_ARM_MAP(s);
    double *w = s->scratch, *y = w + 2 * n;
    int c, k;
    for (c = 0; c < nz; ++c) {
        double *column = J + c * nz, X0 = 0.0, X1 = 0.0, L0 = 0.0, L1 = 0.0;
        for (k = 0; k < 2 * n; ++k) {
            y[k] = 0.0;
        }
        if (c < 2 * n) {
            for (k = 0; k < n; ++k) {
                const double *a = A + 4 * k;
                w[2 * k] = (c == k) - X0;
                w[2 * k + 1] = (c == n + k) - X1;
                X0 += a[0] * w[2 * k] + a[1] * w[2 * k + 1];
                X1 += a[2] * w[2 * k] + a[3] * w[2 * k + 1];
                column[2 * n + k] = gc[2 * k] * w[2 * k] + gc[2 * k + 1] * w[2 * k + 1];
            }
            for (k = 0; k < s->nh; ++k) {
                y[s->h_row[k]] += s->h[k] * w[s->h_col[k]];
            }
        } else {
            k = c - 2 * n;
            y[2 * k] = gmu[2 * k];
            y[2 * k + 1] = gmu[2 * k + 1];
            for (k = 0; k < n; ++k) {
                column[2 * n + k] = 0.0;
            }
        }
        for (k = n - 1; k >= 0; --k) {
            const double *a = A + 4 * k, y0 = y[2 * k], y1 = y[2 * k + 1];
            column[k] = (c == k ? m[k] : 0.0) + y0 + a[0] * L0 + a[2] * L1;
            column[n + k] = (c == n + k ? m[k] : 0.0) + y1 + a[1] * L0 + a[3] * L1;
            {
                const double next0 = -y0 + (1.0 - a[0]) * L0 - a[2] * L1;
                const double next1 = -y1 - a[1] * L0 + (1.0 - a[3]) * L1;
                L0 = next0;
                L1 = next1;
            }
        }
    }
}

/* The residual's scale 1 + sum_j |J_ij| |z_j| of the Newton test, bounded from above by the
 * factors: |M| |dv| + |B|^T (|H| |B| |dv| + |G_mu| |dmu|) and |G_c| |B| |dv|, with |B| bounded
 * by the recursion w_k = x_k - X_k, X_{k+1} = (I - A_k) X_k + A_k x_k taken entrywise in
 * absolute values (exact for links whose COM is on their axis, where each A_k is a multiple
 * of I). Uses scratch. */
static void chaingen_arm_scale(const chaingen_arm_system *s, const double *z, double *scale)
{
    const int n = s->n;
    const double *gmu = CHAINGEN_ARM_GMU(s), *gc = CHAINGEN_ARM_GC(s);
    const double *m = CHAINGEN_ARM_MASS(s), *A = CHAINGEN_ARM_MAP(s);
    double *w = s->scratch, *f = w + 2 * n;
    double X0 = 0.0, X1 = 0.0, L0 = 0.0, L1 = 0.0;
    int k;
    for (k = 0; k < n; ++k) {
        const double *a = A + 4 * k, x0 = fabs(z[k]), x1 = fabs(z[n + k]);
        const double next0 = fabs(1.0 - a[0]) * X0 + fabs(a[1]) * X1 + fabs(a[0]) * x0
                             + fabs(a[1]) * x1;
        const double next1 = fabs(a[2]) * X0 + fabs(1.0 - a[3]) * X1 + fabs(a[2]) * x0
                             + fabs(a[3]) * x1;
        w[2 * k] = x0 + X0;
        w[2 * k + 1] = x1 + X1;
        X0 = next0;
        X1 = next1;
        f[2 * k] = fabs(gmu[2 * k]) * fabs(z[2 * n + k]);
        f[2 * k + 1] = fabs(gmu[2 * k + 1]) * fabs(z[2 * n + k]);
        scale[2 * n + k] = 1.0 + fabs(gc[2 * k]) * w[2 * k] + fabs(gc[2 * k + 1]) * w[2 * k + 1];
    }
    for (k = 0; k < s->nh; ++k) {
        f[s->h_row[k]] += fabs(s->h[k]) * w[s->h_col[k]];
    }
    for (k = n - 1; k >= 0; --k) {
        const double *a = A + 4 * k, f0 = f[2 * k], f1 = f[2 * k + 1];
        scale[k] = 1.0 + m[k] * fabs(z[k]) + f0 + fabs(a[0]) * L0 + fabs(a[2]) * L1;
        scale[n + k] = 1.0 + m[k] * fabs(z[n + k]) + f1 + fabs(a[1]) * L0 + fabs(a[3]) * L1;
        {
            const double next0 = f0 + fabs(1.0 - a[0]) * L0 + fabs(a[2]) * L1;
            const double next1 = f1 + fabs(a[1]) * L0 + fabs(1.0 - a[3]) * L1;
            L0 = next0;
            L1 = next1;
        }
    }
}

#endif /* CHAINGEN_ARM_SOLVE_H */
