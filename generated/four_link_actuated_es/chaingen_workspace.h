/* The workspace of a chaingen solver: its storage, sized by one formula, and the runtime's view
 * of it.
 *
 * A package declares its workspace type from the sizes of its model (<prefix>.h):
 *
 *     typedef struct {
 *         chaingen_workspace_scalars scalars;
 *         const double *arg[ARG]; double *res[RES]; long long int iw[IW]; double w[W];
 *         int ints[CHAINGEN_WORKSPACE_INTS(NZ, NSTAGE)];
 *         double doubles[CHAINGEN_WORKSPACE_DOUBLES(N, NX, NZ, NU, NP, NQ, NSTAGE, ARM_NH,
 *                                                   SENSITIVITIES, CHAIN_STATE, NSEGMENT,
 *                                                   NCONSTRAINT)];
 *     } prefix_workspace;
 *
 * and hands the runtime a chaingen_workspace, pointers into it. The runtime carves `doubles` and
 * `ints` into its arrays (chaingen_runtime.c, carve()) in the order of the terms below, so the
 * formula is stated here once and the carve is tested against it. The workspace holds no pointer
 * into itself: a copy of it is a copy of the solver's state.
 *
 * Plain C99, no allocation, no global state. */
#ifndef CHAINGEN_WORKSPACE_H
#define CHAINGEN_WORKSPACE_H

#include "chaingen_contract.h"

/* The Newton state carried from step to step, and the counters of the last step. Zeroed by
 * workspace_init: no history. */
typedef struct {
    double previous_dt;     /* dt of the step that produced previous_x1 */
    double factors_dt;      /* dt of the factorised Jacobian */
    double proposed_dt;     /* adaptive steps: the controller's next step (0: none yet) */
    double previous_error;  /* adaptive steps: the previous error estimate */
    double composed_dt;     /* composed steps: dt of the step that ended at composed_x1 */
    double energy_ends[3];  /* the energy check: (H, T, S) at energy_x */
    long step_fallbacks;    /* full-Newton fallbacks of the last step */
    long step_splits;       /* halvings of the last step */
    int history;            /* solutions in previous_z: 0 to CHAINGEN_WARM_START_HISTORY */
    int warm_choice;        /* first guess of a chained step: 0 extrapolate from all of
                             * previous_z, 1 the scheme's predictor, d + 1 from the last d */
    int chained;            /* this step continues the previous one */
    int factors_valid;      /* the Jacobian's factors in the workspace are usable */
    int refresh_first;      /* the next solve evaluates the Jacobian at its first guess:
                             * simplified Newton, when the last replaced one evaluated within
                             * it; the chord kept across steps, when the last did not */
    int exact_first;        /* the model's Newton matrix had to be replaced within a recent
                             * solve: so many more solves start with dF/dz instead */
    int energy_valid;       /* energy_ends belong to energy_x */
    int q_valid;            /* q = Q(p) belongs to q_of */
    int composed_valid;     /* composed_x1 and the stages' records are usable */
} chaingen_workspace_scalars;

/* The runtime's view of a package's workspace. */
typedef struct {
    chaingen_workspace_scalars *scalars;
    const double **arg;     /* the generated functions' argument pointers, */
    double **res;           /* result pointers, */
    long long int *iw;      /* and work arrays (sized by the package for its largest function) */
    double *w;
    int *ints;              /* CHAINGEN_WORKSPACE_INTS entries */
    double *doubles;        /* CHAINGEN_WORKSPACE_DOUBLES entries */
} chaingen_workspace;

/* Rows of the sensitivities a step chains: the joint-space state s (2N), or with CHAIN_STATE the
 * whole state x (NX), which s does not determine (es's composed steps). */
#define CHAINGEN_NCHAIN(N, NX, CHAIN_STATE) ((CHAIN_STATE) ? (NX) : 2 * (N))
/* Columns of the sensitivities: the chained state, the inputs, the parameters. */
#define CHAINGEN_NCHAIN_SENS(N, NX, NU, NP, CHAIN_STATE) \
    (CHAINGEN_NCHAIN(N, NX, CHAIN_STATE) + (NU) + (NP))

/* The ints: Newton's pivots (NZ), and per stage of a composed step its history and choice. */
#define CHAINGEN_WORKSPACE_INTS(NZ, NSTAGE) ((NZ) + 2 * (NSTAGE) + 1)

/* The doubles, term by term in the order carve() lays them out:
 *  - z, dz, residual, residual_scale (NZ each);
 *  - the Newton matrix: dense NZ x NZ, or with ARM_NH > 0 es's factors (chaingen_arm_solve.h):
 *    H's nonzeros and 9N more, 15N derived, the reduced N x N matrix and 6N of scratch;
 *  - state[2], candidate, previous_x1, energy_x (NX each), previous_z (HISTORY x NZ);
 *  - q (NQ, at least 1) and q_of (NP): the derived parameters and the p they belong to;
 *  - split_state (MAX_SPLIT x NX), split_inputs (MAX_SPLIT x NU), adaptive_state (4 x NX);
 *  - with SENSITIVITIES: the right-hand sides (NZ x NCHAIN_SENS) and S_z (NCHAIN x NZ);
 *  - with NSTAGE > 0: stage_state (2 x NX), composed_x1 (NX), stage_z (NSTAGE x HISTORY x NZ),
 *    and with SENSITIVITIES the stage's and the accumulated sensitivities (NCHAIN x NCHAIN_SENS
 *    each), and with CHAIN_STATE the maps to joint space: x0_s0 (NX x 2N), s1_x1 (2N x NX), a
 *    column (NX), x0_p (NX x NP), s1_p (2N x NP);
 *  - the runtime's scratch arrays (what were local arrays of the rendered solver): the segment
 *    margins of a step (2 NSEGMENT), the constraint output (NCONSTRAINT + 1), a posture's state
 *    (NX) and its zero rates (N), the adaptive step's joint states start, whole and ends (3 x 2N),
 *    the controller's phi, omega (N each) and held inputs (NU), and with NSTAGE > 0 and
 *    SENSITIVITIES a column of the composed sensitivities (NCHAIN). */
#define CHAINGEN_WORKSPACE_DOUBLES(N, NX, NZ, NU, NP, NQ, NSTAGE, ARM_NH, SENSITIVITIES,           \
                                   CHAIN_STATE, NSEGMENT, NCONSTRAINT)                             \
    (4 * (NZ)                                                                                      \
     + ((ARM_NH) > 0 ? (ARM_NH) + 9 * (N) + 15 * (N) + (N) * (N) + 6 * (N) : (NZ) * (NZ))          \
     + 5 * (NX) + CHAINGEN_WARM_START_HISTORY * (NZ)                                               \
     + ((NQ) > 0 ? (NQ) : 1) + (NP)                                                                \
     + CHAINGEN_MAX_SPLIT * ((NX) + (NU)) + 4 * (NX)                                               \
     + ((SENSITIVITIES) ? (NZ) * CHAINGEN_NCHAIN_SENS(N, NX, NU, NP, CHAIN_STATE)                  \
                              + CHAINGEN_NCHAIN(N, NX, CHAIN_STATE) * (NZ) : 0)                    \
     + ((NSTAGE) > 0 ? 3 * (NX) + (NSTAGE) * CHAINGEN_WARM_START_HISTORY * (NZ) : 0)               \
     + ((NSTAGE) > 0 && (SENSITIVITIES)                                                            \
            ? 2 * CHAINGEN_NCHAIN(N, NX, CHAIN_STATE)                                              \
                  * CHAINGEN_NCHAIN_SENS(N, NX, NU, NP, CHAIN_STATE) : 0)                          \
     + ((NSTAGE) > 0 && (SENSITIVITIES) && (CHAIN_STATE)                                           \
            ? 4 * (N) * (NX) + (NX) + (NX) * (NP) + 2 * (N) * (NP) : 0)                         \
     + 2 * (NSEGMENT) + (NCONSTRAINT) + 1 + (NX) + (N) + 6 * (N) + 2 * (N) + (NU)                  \
     + ((NSTAGE) > 0 && (SENSITIVITIES) ? CHAINGEN_NCHAIN(N, NX, CHAIN_STATE) : 0))

#endif /* CHAINGEN_WORKSPACE_H */
