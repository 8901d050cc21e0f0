/* A hand-written model for the runtime's own tests: a planar pendulum with a linear spring from
 * its bob to a fixed anchor, gravity, an actuated joint with viscous damping, and the spring's
 * stiffness as a run-time parameter. Plain C, no SymPy and no CasADi: the model functions are
 * written by hand in CasADi's calling convention and fill a chaingen_model.
 *
 * Mechanics (SI): bob of mass M at r(phi) = L (sin phi, -cos phi), phi from the downward
 * vertical; inertia I = M L^2; potential V(phi) = -M g L cos phi + k/2 (|r - A| - l0)^2 with the
 * anchor A; joint torque tau = u[0] and damping torque -c omega.
 *
 * State x = (phi, omega) (NX = 2, the joint-space state s itself, phi unwrapped). Scheme: the
 * implicit midpoint rule, with the increments as Newton unknowns z = (dphi, domega) (NZ = 2):
 *     phi_m = phi0 + dphi / 2,   omega_m = omega0 + domega / 2,
 *     F0 = dphi - dt omega_m,
 *     F1 = I domega + dt (V'(phi_m) - tau + c omega_m),
 * and x1 = (phi0 + dt omega_m, omega0 + domega) (phi1 from the rates, so that ds1/dz is not
 * symmetric). Energy flows of a step: W = tau (phi1 - phi0), D = c omega_m^2 dt. The midpoint rule
 * keeps H1 - H0 = W - D up to the midpoint quadrature error of V over the step,
 *     H1 - H0 - (W - D) = V(phi1) - V(phi0) - V'(phi_m) (phi1 - phi0) = O(dphi^3)
 * (pendulum_balance_defect computes it), since T1 - T0 = I omega_m domega exactly.
 *
 * The model's variants (pendulum_variant) switch the runtime's features on and off; the knobs
 * (pendulum_knobs, global: the tests are single-threaded) provoke each failure status. */
#ifndef PENDULUM_MODEL_H
#define PENDULUM_MODEL_H

#include "chaingen_runtime.h"

#define PENDULUM_N 1
#define PENDULUM_NX 2
#define PENDULUM_NZ 2
#define PENDULUM_MAX_NU 1
#define PENDULUM_MAX_NP 1
#define PENDULUM_MAX_NQ 1
#define PENDULUM_MAX_NSTAGE 9
#define PENDULUM_NCONSTRAINT 1
/* The most arguments and results of any model function, and the work arrays (unused). */
#define PENDULUM_ARG 5
#define PENDULUM_RES 4
#define PENDULUM_IW 1
#define PENDULUM_W 1

/* Physical constants. */
#define PENDULUM_MASS 1.0
#define PENDULUM_LENGTH 1.0
#define PENDULUM_GRAVITY 9.81
#define PENDULUM_STIFFNESS 5.0       /* k when the model has no parameters, and p's usual value */
#define PENDULUM_DAMPING 0.3         /* c of the damped variants */
/* Spring segments: the run's tolerance relative to the geometry's size, and the scene reader's
 * (a start shorter than that is collapsed): start_margin = their ratio. */
#define PENDULUM_RUN_TOLERANCE 1e-6
#define PENDULUM_START_TOLERANCE 1e-9
/* The anchor of the "collapse" variant lies on the bob's circle at this angle (l0 = 0 there:
 * the spring's potential stays smooth through zero length). */
#define PENDULUM_COLLAPSE_ANGLE 1.0

/* Composition of the step. */
enum {
    PENDULUM_PLAIN = 0,      /* the midpoint step alone: order 2 */
    PENDULUM_YOSHIDA4 = 1,   /* triple jump, 3 stages: order 4 */
    PENDULUM_SUZUKI4 = 2,    /* Suzuki's 5 stages: order 4 */
    PENDULUM_KAHAN_LI6 = 3   /* Kahan and Li's 9 stages (s9odr6a): order 6 */
};

typedef struct {
    int actuated;        /* nu = 1 (else 0) */
    int parameters;      /* np = 1: p = (k) (else k = PENDULUM_STIFFNESS fixed) */
    int damped;          /* c = PENDULUM_DAMPING (else 0) */
    int flows;           /* next_state reports (W, D) */
    int segments;        /* the spring segment is watched (segment_margins) */
    int collapse;        /* the anchor on the bob's circle (zero length at the collapse angle) */
    int energy_check;    /* energy_terms present, default energy_tol 0.01 */
    int sensitivities;   /* sensitivity_rhs and sensitivity_map */
    int chain_state;     /* composed sensitivities chained in x (joint_maps, identity here) */
    int holding;         /* holding_torques present */
    int control;         /* applied_torques present: tau = u + dt domega + phi0^2 (a stand-in
                          * for a control law solved in the step: it reads z, x0, u and dt) */
    int held_control;    /* the model's held_control: its law held over the step */
    double held_gain;    /* K != 0: the step's torque is u - K phi0, a law of the step's start
                          * held over it (as a scene's sampled law), and applied_torques (with
                          * control) returns it, whatever z and dt; the sensitivities do not
                          * see the law */
    int composition;     /* PENDULUM_PLAIN, _YOSHIDA4, _SUZUKI4, _KAHAN_LI6 */
    int error_entries;   /* 1 (angles) or 2 (angles and rates); 0: 2 */
} pendulum_variant;

/* The failure knobs. A knob with a dt applies only to steps longer than above_dt (0: to all). */
enum {
    PENDULUM_F_PARAMETERS,
    PENDULUM_F_INITIAL_STATE,
    PENDULUM_F_OUTPUTS,
    PENDULUM_F_HOLDING_TORQUES,
    PENDULUM_F_RESIDUAL,
    PENDULUM_F_RESIDUAL_JACOBIAN,
    PENDULUM_F_PREDICTOR,
    PENDULUM_F_NEXT_STATE,
    PENDULUM_F_SEGMENT_MARGINS,
    PENDULUM_F_ENERGY_TERMS,
    PENDULUM_F_SENSITIVITY_RHS,
    PENDULUM_F_SENSITIVITY_MAP,
    PENDULUM_F_JOINT_MAPS,
    PENDULUM_F_APPLIED_TORQUES,
    PENDULUM_NFUNCTIONS
};

typedef struct {
    unsigned fail_mask;      /* bit (1u << PENDULUM_F_x): that function returns 1 */
    int nan_residual;        /* 1: F (residual and residual_jacobian) NaN; 2: residual() only */
    int zero_jacobian;       /* dF/dz = 0 */
    double jacobian_scale;   /* dF/dz scaled by this (0: 1); 1/1.9 makes Newton crawl (rate 0.9) */
    double above_dt;         /* the knobs above (and fail_mask's step functions) act when
                              * |dt| > this */
    double energy_jump;      /* energy_terms reports H + energy_jump phi */
    double energy_cancelled; /* energy_terms reports S, the magnitude of H's terms, this much
                              * above |T| + |V|: terms that cancel in H */
    double state_kick;       /* next_state adds this to omega1 (an error no step length
                              * removes) */
    double angle_kick;       /* next_state adds this to phi1: the round-off of an angle taken
                              * from coordinates, absolute, whatever the step length */
    double predictor_bias;   /* added to the predictor's domega: a poor first guess */
    double cubic;            /* F1 becomes F1 + cubic F1^3 (same root): Newton from a poor
                              * guess takes many iterations, from a good one few */
    double fold;             /* > 0: F1 becomes F1^2 + fold (steps longer than above_dt): no
                              * root, as where a step runs past a fold of its root */
    double residual_noise;   /* F gains a pseudo-random error of this size at every
                              * evaluation: round-off of terms larger than the Jacobian's */
    unsigned noise_state;    /* its generator's state */
    int nan_torques;         /* applied_torques returns NaN */
    int phi_limited;         /* next_state fails (returns 1) on a step from phi0 > phi_limit */
    double phi_limit;
    long calls[PENDULUM_NFUNCTIONS];   /* evaluations of each function */
} pendulum_knobs;

extern pendulum_knobs pendulum_knob;

/* Fill *model for the variant (and make it the model the functions evaluate: one at a time).
 * The knobs are reset. */
void pendulum_model_init(chaingen_model *model, const pendulum_variant *variant);
void pendulum_knobs_reset(void);

/* V(phi), V'(phi), V''(phi) and dV'/dk at stiffness k, of the current variant. */
void pendulum_potential(double phi, double k, double out[4]);
/* H of state x at stiffness k. */
double pendulum_energy(const double *x, double k);
/* H1 - H0 - (W - D) of the midpoint rule from phi0 to phi1 (see above). */
double pendulum_balance_defect(double phi0, double phi1, double k);
/* Damping c of the current variant. */
double pendulum_damping(void);

#endif /* PENDULUM_MODEL_H */
