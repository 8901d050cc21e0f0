/* chaingen's C runtime: the solver algorithms, written once, that every generated package calls.
 *
 * Newton's method with its options and status codes, the fallback ladder (warm start retried
 * from the predictor, kept Jacobian replaced by full Newton, the step split into halves), the
 * energy check, adaptive steps, the composed steps of order 4 and 6, the step sensitivities and
 * their chain rule through a composition, and the simulate loops (open, observed, controlled).
 * The model is reached through a table of function pointers and sizes, chaingen_model, that a
 * generated package fills in; a package's exported functions are thin wrappers over the
 * functions below, with the same signatures whatever the scene's features.
 *
 * Linkage: by default the functions below have external linkage (the runtime's own tests link
 * it as an ordinary object). A package compiles it into its own source with
 *     #define CHAINGEN_LINKAGE static
 *     #include "chaingen_runtime.c"
 * so that nothing but the package's prefixed API is exported and two packages link together.
 *
 * Plain C99: no allocation, no global mutable state; every array is the caller's or the
 * workspace's. Matrices are dense and column-major. Units SI. */
#ifndef CHAINGEN_RUNTIME_H
#define CHAINGEN_RUNTIME_H

#include <stddef.h>

#include "chaingen_contract.h"
#include "chaingen_workspace.h"

#ifndef CHAINGEN_LINKAGE
#define CHAINGEN_LINKAGE
#endif

/* A generated model function, CasADi's calling convention: inputs and outputs by position (a NULL
 * output is skipped), integer and real work arrays, memory index. Nonzero: evaluation failed. */
typedef int (*chaingen_function)(const double **arg, double **res, long long int *iw, double *w,
                                 int mem);

/* The model of one package. Sizes first, then the generated functions; a function the package
 * does not have is NULL (the entry points that need it return CHAINGEN_UNAVAILABLE).
 *
 * Argument order of the functions (q = Q(p), the derived parameters, present when np > 0; u
 * present when nu > 0):
 *   parameters        (p) -> (q)
 *   initial_state     (phi, phidot, q) -> (x)
 *   outputs           (x, q) -> (phi, omega, H, constraint[nconstraint])
 *   holding_torques   (phi, q) -> (tau[n_joints])
 *   residual          (z, x0, u, q, dt[, y]) -> (F)          y: when ny > 0
 *   residual_jacobian (z, x0, u, q, dt) -> (F, dF/dz)          dense packages (arm_nh == 0)
 *   newton_factors    (z, x0, u, q, dt[, y]) -> (F, factors)   arm solve (arm_nh > 0)
 *   chord_factors     (z, x0, u, q, dt[, y]) -> (F, factors)   the same F and layout, H of
 *                                                   the springs' quadrature alone, without the
 *                                                   exact gradient's correction: the chord's
 *                                                   Newton matrix (arm solve, exact gradient)
 *   step_constants    (x0, u, q, dt) -> (y[ny])   what those three compute from the step's
 *                                                   start alone (generate/step_constants.py)
 *   predictor         (x0, q, dt) -> (z)
 *   next_state        (z, x0, u, q, dt) -> (x1, flows[2] when flows)
 *   segment_margins   (x0, x1, q) -> (margins[2 nsegment])     when nsegment > 0
 *   energy_check      (x, q) -> (H, T, S)  S: sum of |H's terms|  when energy_check
 *   sensitivity_rhs   (z, x0, u, q, dt) -> (R[nz x ncols])     when sensitivities
 *   sensitivity_map   (z, x0, u, q, dt) -> (S_z, S_s0, S_u, S_p)  when sensitivities
 *   joint_maps        (x0, x1, q) -> (x0_s0, s1_x1, x0_p, s1_p)   composed, chain_state
 *   newton_matrix     (z, x0, u, q, dt) -> (F, A)   A ~ dF/dz, Newton's matrix in place of
 *                                                   dF/dz where the scheme has one
 *   applied_torques   (z, x0, u, q, dt) -> (tau[nu])   the torques the actuated joints apply
 *                                                   over the step (a control law solved in
 *                                                   it, issue 34): control_torques */
typedef struct {
    int n_joints;           /* links and revolute joints N */
    int nx;                 /* entries of a state x */
    int nz;                 /* Newton unknowns of one step */
    int nu;                 /* inputs u: torques of the actuated joints (0: none) */
    int np;                 /* run-time parameters p (0: none) */
    int nq;                 /* derived parameters q = Q(p) */
    int nsample;            /* entries of a sample row */
    int nconstraint;        /* entries of the constraint output */
    int nsegment;           /* spring segments watched for collapse (0: no springs) */
    int order;              /* 2, 4 or 6 */
    int nstage;             /* stages of the composed step (0: the scheme's step alone) */
    const double *stages;   /* their fractions of dt, summing to 1 */
    int error_entries;      /* entries of s the adaptive error test takes: N or 2N */
    int flows;              /* next_state reports the step's energy flows */
    int energy_check;       /* a converged step is checked against the energy balance */
    int sensitivities;      /* the package has the step sensitivities */
    int chain_state;        /* composed sensitivities chain in x, not s */
    int held_control;       /* the step's control law is held from its start (a scene's
                             * control.law = "sampled"): its hold period is the step, so
                             * adaptive steps (rtol or atol > 0), which would make it the
                             * adaptive step's instead of dt, are BAD_ARGUMENT, and a split
                             * step's halves hold the whole step's torque (applied_torques
                             * then reads x0, u and q alone: u + law(x0)) */
    double start_margin;    /* a start state's segment margins must be at least this */
    const double *p_lower;  /* per parameter: its lower bound, */
    const int *p_inclusive; /* and whether p_i may equal it */
    int arm_nh;             /* es's arm solve: structural nonzeros of H (0: dense LU) */
    int ny;                 /* the step's constants (0: none); they lead the work array w */
    const int *arm_h_row;   /* their rows and columns on the arms */
    const int *arm_h_col;
    chaingen_options defaults;  /* the package's Newton defaults */
    chaingen_function parameters;
    chaingen_function initial_state;
    chaingen_function outputs;
    chaingen_function holding_torques;
    chaingen_function residual;
    chaingen_function residual_jacobian;
    chaingen_function newton_factors;
    chaingen_function chord_factors;
    chaingen_function step_constants;
    chaingen_function predictor;
    chaingen_function next_state;
    chaingen_function segment_margins;
    chaingen_function energy_terms;
    chaingen_function sensitivity_rhs;
    chaingen_function sensitivity_map;
    chaingen_function joint_maps;
    chaingen_function newton_matrix;
    chaingen_function applied_torques;
} chaingen_model;

/* The size a chaingen_dimension query names, -1 for an unknown one. */
CHAINGEN_LINKAGE long chaingen_dimension(const chaingen_model *model, int which);

/* workspace->ints and workspace->doubles hold at least this many entries for the model (the
 * formula of chaingen_workspace.h at the model's sizes). */
CHAINGEN_LINKAGE long chaingen_workspace_doubles(const chaingen_model *model);
CHAINGEN_LINKAGE long chaingen_workspace_ints(const chaingen_model *model);

/* Every field of the workspace's scalars and arrays zeroed: no history carried. */
CHAINGEN_LINKAGE void chaingen_workspace_init(const chaingen_model *model,
                                              const chaingen_workspace *workspace);

CHAINGEN_LINKAGE void chaingen_default_options(const chaingen_model *model,
                                               chaingen_options *options);

/* The entry points. Their meaning is that of the package's header (templates/solver.h.j2):
 * nu and np must be the model's (BAD_ARGUMENT otherwise); u and p may be NULL only when their
 * size is 0 (simulate and simulate_observed: u NULL is zero torques). A NULL workspace (a view
 * whose scalars are NULL) is BAD_ARGUMENT, and so are options with rtol or atol other than 0 in
 * the entry points of one fixed step (step, step_sensitivities, control_torques). */
CHAINGEN_LINKAGE int chaingen_initial_state(const chaingen_model *model, const double *phi,
                                            const double *phidot, const double *p, int np,
                                            double *x, const chaingen_workspace *workspace);
CHAINGEN_LINKAGE int chaingen_outputs(const chaingen_model *model, const double *x,
                                      const double *p, int np, double *phi, double *omega,
                                      double *energy, double *constraint_error,
                                      const chaingen_workspace *workspace);
CHAINGEN_LINKAGE int chaingen_holding_torques(const chaingen_model *model, const double *phi,
                                              const double *p, int np, double *tau,
                                              const chaingen_workspace *workspace);
CHAINGEN_LINKAGE int chaingen_residual(const chaingen_model *model, const double *z,
                                       const double *x0, const double *u, int nu,
                                       const double *p, int np, double dt, double *residual,
                                       const chaingen_workspace *workspace);
CHAINGEN_LINKAGE int chaingen_residual_jacobian(const chaingen_model *model, const double *z,
                                                const double *x0, const double *u, int nu,
                                                const double *p, int np, double dt,
                                                double *residual, double *jacobian,
                                                const chaingen_workspace *workspace);
CHAINGEN_LINKAGE int chaingen_step(const chaingen_model *model, const double *x0,
                                   const double *u, int nu, const double *p, int np, double dt,
                                   double *x1, double *flows, const chaingen_options *options,
                                   const chaingen_workspace *workspace, int *iterations);
CHAINGEN_LINKAGE int chaingen_step_sensitivities(const chaingen_model *model, const double *x0,
                                                 const double *u, int nu, const double *p,
                                                 int np, double dt, double *x1, double *ds_ds,
                                                 double *ds_du, double *ds_dp,
                                                 const chaingen_options *options,
                                                 const chaingen_workspace *workspace,
                                                 int *iterations);
CHAINGEN_LINKAGE int chaingen_control_torques(const chaingen_model *model, const double *x0,
                                              const double *u, int nu, const double *p, int np,
                                              double dt, double *tau, double *x1,
                                              const chaingen_options *options,
                                              const chaingen_workspace *workspace,
                                              int *iterations);
CHAINGEN_LINKAGE long chaingen_sample_count(const chaingen_model *model, long n_steps,
                                            long every);
CHAINGEN_LINKAGE int chaingen_simulate_observed(const chaingen_model *model, const double *x0,
                                                double t0, double dt, long n_steps, long every,
                                                const double *u, int nu, const double *p,
                                                int np, const chaingen_options *options,
                                                const chaingen_workspace *workspace,
                                                double *samples, double *x_final,
                                                chaingen_stats *stats,
                                                chaingen_observer observer, void *context,
                                                long interval, chaingen_control *control);
CHAINGEN_LINKAGE int chaingen_simulate_controlled(const chaingen_model *model, const double *x0,
                                                  double t0, double dt, long n_steps,
                                                  long every, chaingen_controller controller,
                                                  void *context, long hold, const double *p,
                                                  int np, const chaingen_options *options,
                                                  const chaingen_workspace *workspace,
                                                  double *samples, double *torques,
                                                  double *x_final, chaingen_stats *stats,
                                                  chaingen_control *control);

#endif /* CHAINGEN_RUNTIME_H */
