/* The C contract of chaingen's runtime: status codes, options, counters, callback types
 * and constants. Rendered from chaingen/runtime/contract.py by
 * chaingen.generate.interface.contract_header(). Do not edit. */

#ifndef CHAINGEN_CONTRACT_H
#define CHAINGEN_CONTRACT_H

/* Status codes. */
#define CHAINGEN_OK 0                /* success */
#define CHAINGEN_NOT_CONVERGED 1     /* Newton: max_iterations reached without convergence */
#define CHAINGEN_SINGULAR_JACOBIAN 2 /* Newton: no usable pivot in the LU factorisation */
#define CHAINGEN_NONFINITE 3         /* NaN or Inf in the residual or the iterate */
#define CHAINGEN_BAD_ARGUMENT 4      /* a null pointer, dt <= 0 or not finite, a NaN or Inf in a
                                      * state, posture or input u, n_steps < 0, every < 1,
                                      * interval < 1, hold < 1, more sample rows than memory can
                                      * address, an unknown reuse_jacobian or a bad rtol, atol or
                                      * energy_tol */
#define CHAINGEN_EVALUATION_FAILED 5 /* a generated function reported an error */
#define CHAINGEN_SEGMENT_COLLAPSED 6 /* a spring segment came within its tolerance of the
                                      * geometry's size of zero length, or passed through it
                                      * (turned by 90 degrees or more in one step), or a start
                                      * state or posture has one of zero length (under 1e-9 of
                                      * that size, the scene reader's limit): its direction is
                                      * undefined there (docs/model.md, section 2) */
#define CHAINGEN_INTERRUPTED 7       /* simulate_observed or simulate_controlled: the observer,
                                      * the controller or control->stop asked to stop */
#define CHAINGEN_STEP_TOO_SMALL 8    /* adaptive steps: the error test or Newton failed at a step
                                      * below 1e-12 dt */
#define CHAINGEN_ENERGY_JUMP 9       /* the converged step missed the energy balance by more than
                                      * energy_tol times the kinetic energy at its ends: a
                                      * spurious root of a step too long for the motion */
#define CHAINGEN_BAD_PARAMETER 10    /* a run-time parameter p_i is not finite or below its lower
                                      * bound, a value the scene format refuses (see p above) */
#define CHAINGEN_UNAVAILABLE 11      /* the package was generated without this function:
                                      * step_sensitivities without the sensitivities,
                                      * holding_torques and simulate_controlled without actuated
                                      * joints, control_torques without a control law */

/* Values of the option reuse_jacobian. */
#define CHAINGEN_JACOBIAN_EVERY_ITERATE 0  /* full Newton */
#define CHAINGEN_JACOBIAN_ACROSS_STEPS 1   /* simplified Newton */
#define CHAINGEN_JACOBIAN_PER_STEP 2       /* Newton-chord: once a step */
#define CHAINGEN_JACOBIAN_CHORD_ACROSS_STEPS 3 /* Newton-chord, kept across chained steps */

/* Newton options (each package's defaults: <prefix>_default_options). */
typedef struct {
    int max_iterations;     /* default 20; bounds the work of one step */
    double update_rtol;     /* default 1e-10 */
    double update_atol;     /* default 1e-13 */
    double residual_tol;    /* default 1e-8; units of F */
    int warm_start;         /* default 1; continue from the previous solutions */
    int reuse_jacobian;     /* default 0; one of the JACOBIAN_* modes */
    double energy_tol;      /* default 0.01; vi, midpoint, spatial es: a step with |H_1 - H_0 - W + D| > energy_tol (T_0 + T_1) is refused and split; 0: no check */
    double rtol;            /* default 0.0; adaptive steps: relative local error, 0 or >= 1e-14; 0 with atol 0: fixed steps of dt */
    double atol;            /* default 0.0; adaptive steps: absolute local error (rad, rad/s), 0 or >= 1e-14 */
} chaingen_options;

/* Counters of one simulate call. */
typedef struct {
    long steps;             /* steps completed (the failing one excluded) */
    long newton_iterations; /* Newton iterations (linear solves) over all completed steps */
    int max_newton_iterations; /* the most a single completed step took */
    int failed_iterations;  /* iterations spent in the failing step, 0 if none failed */
    long full_newton_fallbacks; /* steps whose kept Jacobian failed and that full Newton solved */
    long split_steps;       /* steps that Newton failed on whole and that were taken as two halves (recursively) */
    long accepted_steps;    /* steps of the scheme taken: steps with fixed steps; adaptive: the accepted ones */
    long rejected_steps;    /* adaptive: steps refused by the error test or Newton */
    double smallest_dt;     /* the shortest accepted step (s) */
    double largest_dt;      /* the longest accepted step (s) */
} chaingen_stats;

/* Shared with a running simulate_observed or simulate_controlled. */
typedef struct {
    volatile int stop;      /* set nonzero to stop the run after the current step (status INTERRUPTED) */
    volatile long steps;    /* steps completed so far, written after every step */
} chaingen_control;

typedef int (*chaingen_observer)(long steps, void *context);

typedef int (*chaingen_controller)(long step, double t, const double *phi, const double *omega,
                                   double *u, void *context);

/* The sizes <prefix>_dimension(which) answers (-1 for another which). */
#define CHAINGEN_DIMENSION_N_JOINTS 0      /* links and revolute joints */
#define CHAINGEN_DIMENSION_NX 1            /* entries of a state x */
#define CHAINGEN_DIMENSION_NZ 2            /* Newton unknowns z of one step */
#define CHAINGEN_DIMENSION_NU 3            /* inputs u: torques of the actuated joints (0: none) */
#define CHAINGEN_DIMENSION_NP 4            /* run-time parameters p (0: none) */
#define CHAINGEN_DIMENSION_NSAMPLE 5       /* entries of one sample row of simulate */
#define CHAINGEN_DIMENSION_NCONSTRAINT 6   /* structural constraints of a state */
#define CHAINGEN_DIMENSION_ORDER 7         /* order of the step: 2, 4 or 6 */
#define CHAINGEN_DIMENSION_NSTAGE 8        /* stages of a composed step (0: the scheme's step alone) */
#define CHAINGEN_DIMENSION_SENSITIVITIES 9 /* 1 when the package has step_sensitivities */

/* Constants of the runtime's algorithms. */
#define CHAINGEN_WARM_START_HISTORY 3  /* solutions of chained steps kept for the warm start */
#define CHAINGEN_REFRESH_RATE 0.1      /* a kept Jacobian is evaluated anew when updates shrink by less than this */
#define CHAINGEN_SIMPLIFIED_MARGIN 0.1 /* simplified Newton stops at this fraction of the tolerance */
#define CHAINGEN_CHORD_MARGIN 1e-3     /* Newton-chord stops at this fraction of the tolerance */
#define CHAINGEN_MAX_SPLIT 4           /* halvings of a step Newton fails on whole */
#define CHAINGEN_MIN_TOLERANCE 1e-14   /* adaptive steps: rtol and atol are 0 or at least this */
#define CHAINGEN_MIN_STEP_FRACTION 1e-12 /* adaptive steps: STEP_TOO_SMALL below this fraction of dt */

#endif /* CHAINGEN_CONTRACT_H */
