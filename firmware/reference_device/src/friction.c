/*
 * friction.c - the friction compensator of SPEC 10.1 step 5, written from SPEC's words.
 *
 * Every model follows one branch coordinate x in [0, 2] along the angle psi travelled
 * since the last velocity reversal, dx/dpsi = (sigma / T_c) g(x), with
 *   g(x) = (2 - x)^alpha          (SFM, DHM)
 *   g(x) = f(x), the slope table  (DB-SFM, DB-DHM; linear between its points)
 * integrated in closed form over each increment (never an Euler step), so the result
 * does not depend on the step size.  Torque:
 *   SFM types:  T = s (x - 1) T_c;  a reversal goes on from x = 1 + s T / T_c
 *   DHM types:  T = T_k + s x T_c;  a reversal pushes T_k = T and restarts from x = 0
 *
 * The stack rules of SPEC 10.1, as this file does them (it agrees with the simulator's
 * friction_step to ~1e-7 in-oz; tests/firmware checks it):
 *   - the first motion after boot or activation (torque 0, no direction yet) moves
 *     along the outer branch: T_k is the opposite Coulomb level, -s T_c;
 *   - the stack holds the reversal torques above that outer-branch start; a branch
 *     "closes" its minor loop when it reaches the reversal torque before its own
 *     (x = |T_k - T_(k-1)| / T_c): the increment is split exactly there, both torques
 *     are popped and the rest of the increment travels the restored branch;
 *   - eps = T_c / 400 is applied at a reversal: a branch that ended within eps of its
 *     closure point counts as closed before the new reversal is pushed;
 *   - a full stack (64) at a reversal falls back to the outer branch of the direction
 *     being left, then the reversal is pushed; EVENT FRICTION_COMP_RESET.
 */
#include <math.h>

#include "device.h"

#define STACK_SIZE 63            /* 62 reversals + the outer-branch start: the simulator's 64 entries hold
                                   both Coulomb levels and 62 reversals */

static int s_dir;                 /* sgn of the motion, 0: none yet */
static double x_branch, torque;
static double stack[STACK_SIZE];  /* DHM reversal torques; stack[n-1] is T_k */
static int n_stack;

static uint8_t model;
static double sigma, coulomb, alpha;
static int n_points;
static double tx[64], ts[64];

void friction_reset(void)
{
    const uint8_t *t = dev.table;
    int i;
    model = hfb_get_u8(t + HFB_PARAM_FRICTION_COMP_MODEL_OFFSET);
    sigma = (double)hfb_get_f32(t + HFB_PARAM_FRICTION_COMP_SIGMA_OFFSET);
    coulomb = (double)hfb_get_f32(t + HFB_PARAM_FRICTION_COMP_COULOMB_OFFSET);
    alpha = (double)hfb_get_f32(t + HFB_PARAM_FRICTION_COMP_ALPHA_OFFSET);
    n_points = hfb_get_u8(t + HFB_PARAM_FRICTION_COMP_TABLE_POINTS_OFFSET);
    for (i = 0; i < n_points; i++) {
        tx[i] = (double)hfb_get_f32(t + HFB_PARAM_FRICTION_COMP_TABLE_X_OFFSET + 4u * (unsigned)i);
        ts[i] = (double)hfb_get_f32(t + HFB_PARAM_FRICTION_COMP_TABLE_SLOPE_OFFSET + 4u * (unsigned)i);
    }
    /* SPEC 11.1: at every activation the compensator restarts, torque 0, no direction */
    s_dir = 0;
    x_branch = 1.0;
    torque = 0.0;
    n_stack = 0;
}

static int is_dhm(void)
{
    return model == 1u || model == 3u;
}

/* Travel along g(x) = (2 - x)^alpha from x, at most psi and at most up to x_cap: with
   u = 2 - x, du/dpsi = -k u^alpha, so u^(1-alpha) changes linearly in psi (alpha = 1:
   u decays exponentially).  Returns the new x; *psi keeps what was not travelled. */
static double advance_power(double x, double *psi, double x_cap, double k)
{
    double u = 2.0 - x, uc = 2.0 - x_cap, need, w;
    if (x >= x_cap) {
        return x;
    }
    if (fabs(alpha - 1.0) < 1e-12) {
        need = uc > 0.0 ? log(u / uc) / k : INFINITY;
    } else if (alpha < 1.0 || uc > 0.0) {
        need = (pow(u, 1.0 - alpha) - pow(uc, 1.0 - alpha)) / ((1.0 - alpha) * k);
    } else {
        need = INFINITY;                          /* alpha > 1 never reaches x = 2 */
    }
    if (*psi >= need) {
        *psi -= need;
        return x_cap;
    }
    if (fabs(alpha - 1.0) < 1e-12) {
        x = 2.0 - u * exp(-k * *psi);
    } else {
        w = pow(u, 1.0 - alpha) - (1.0 - alpha) * k * *psi;
        x = w <= 0.0 ? 2.0 : 2.0 - pow(w, 1.0 / (1.0 - alpha));
    }
    *psi = 0.0;
    return x < x_cap ? x : x_cap;
}

/* The same along the slope table, segment by segment: on a segment f = f0 + m (x - x0),
   so dpsi = dx / (k f) integrates to a logarithm (m != 0) or a straight line (m = 0). */
static double advance_table(double x, double *psi, double x_cap, double k)
{
    int i = 0;
    while (*psi > 0.0 && x < x_cap) {
        double x0, x1, end, f0, m, fx, fb, need;
        while (i + 2 < n_points && x >= tx[i + 1]) {
            i++;
        }
        x0 = tx[i];
        x1 = tx[i + 1];
        f0 = ts[i];
        m = (ts[i + 1] - f0) / (x1 - x0);
        end = x1 < x_cap ? x1 : x_cap;
        fx = f0 + m * (x - x0);
        fb = f0 + m * (end - x0);
        if (fx <= 0.0) {
            break;                                /* slope 0: the branch has ended */
        }
        if (m == 0.0) {
            need = (end - x) / (k * fx);
        } else if (fb <= 0.0) {
            need = INFINITY;                      /* f reaches 0 only asymptotically */
        } else {
            need = log(fb / fx) / (k * m);
        }
        if (*psi < need) {
            x = m == 0.0 ? x + k * fx * *psi : x + (fx * exp(k * m * *psi) - fx) / m;
            *psi = 0.0;
            return x < end ? x : end;
        }
        *psi -= need;
        x = end;
    }
    return x;
}

static double advance(double x, double *psi, double x_cap, double k)
{
    return model >= 2u ? advance_table(x, psi, x_cap, k) : advance_power(x, psi, x_cap, k);
}

/* the outer branch in direction s starts from the opposite Coulomb level */
static void stack_base(int s)
{
    n_stack = 1;
    stack[0] = -(double)s * coulomb;
}

/* x at which the current DHM branch meets the reversal before it (2: never) */
static double closure_x(void)
{
    double d;
    if (n_stack < 2) {
        return 2.0;
    }
    d = fabs(stack[n_stack - 1] - stack[n_stack - 2]) / coulomb;
    return d < 2.0 ? d : 2.0;
}

/* a closed minor loop is forgotten (Masing's rule): its two reversal torques go */
static void pop_pair(int s)
{
    n_stack -= 2;
    if (n_stack <= 0) {
        stack_base(s);
    }
}

double friction_step(double dphi)
{
    int sn;
    double psi, k;
    if (dphi == 0.0 || coulomb <= 0.0) {
        return torque;                            /* no motion changes nothing */
    }
    sn = dphi > 0.0 ? 1 : -1;
    psi = fabs(dphi);
    k = sigma / coulomb;
    if (s_dir == 0) {                             /* first motion: the outer branch */
        s_dir = sn;
        stack_base(sn);
    } else if (sn != s_dir && is_dhm()) {
        /* a branch that ended within eps of its closure point closed its loop; then the
           reversal is remembered (a full stack first falls back to the outer branch) */
        while (n_stack >= 2
               && (double)s_dir * (torque - stack[n_stack - 1]) / coulomb + 1.0 / 400.0 >= closure_x()) {
            pop_pair(s_dir);
        }
        if (n_stack >= STACK_SIZE) {
            stack_base(s_dir);
            event_send(HFB_PKT_EVENT_LEVEL_WARNING, HFB_EVT_FRICTION_COMP_RESET,
                       "friction compensator: reversal stack full, reset to the outer branch");
        }
        stack[n_stack++] = torque;
        s_dir = sn;
    } else if (sn != s_dir) {
        s_dir = sn;
    }
    if (!is_dhm()) {
        /* SFM types: the branch through the current torque, x = 1 + s T / T_c */
        double x0 = 1.0 + (double)s_dir * torque / coulomb;
        x0 = x0 < 0.0 ? 0.0 : (x0 > 2.0 ? 2.0 : x0);
        x_branch = advance(x0, &psi, 2.0, k);
        torque = (double)s_dir * (x_branch - 1.0) * coulomb;
        return torque;
    }
    /* DHM types: travel the branch from T_k; reaching the reversal before it closes the
       minor loop exactly there, and the rest of the travel goes on along the restored
       branch */
    for (;;) {
        double tk = stack[n_stack - 1];
        double x0 = (double)s_dir * (torque - tk) / coulomb;
        double cap = closure_x();
        x0 = x0 < 0.0 ? 0.0 : (x0 > 2.0 ? 2.0 : x0);
        x_branch = advance(x0, &psi, cap, k);
        if (n_stack >= 2 && x_branch >= cap) {
            double tk1 = stack[n_stack - 2];
            torque = fabs(tk - tk1) <= 2.0 * coulomb ? tk1 : tk + (double)s_dir * 2.0 * coulomb;
            pop_pair(s_dir);
            if (psi > 0.0) {
                continue;
            }
            return torque;
        }
        torque = tk + (double)s_dir * x_branch * coulomb;
        return torque;
    }
}
