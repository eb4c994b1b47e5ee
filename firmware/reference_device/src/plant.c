/*
 * plant.c - the stand-in plant.  It is NOT a model of the rig; it only makes every
 * HIGH_RATE and HOUSEKEEPING channel move plausibly, in its units, so a host sees a
 * live device.  A firmware engineer replaces this file with the board's drivers.
 *
 * Two axes, each a damped double integrator:
 *   outer (coarse, BLDC):  J1 phi1'' = u1 - u2 - c1 phi1'
 *   inner (fine, VCM, the LOS): relative to the outer axis through a flexure spring,
 *       J2 phi2'' = u2 - k (phi2 - phi1) - c2 (phi2' - phi1')
 * The base does not move, so the gyro reads phi2' and the autocollimator phi2 (both
 * inertial = relative to the base).  Integrated with semi-implicit Euler at the control
 * period: stable for these constants.
 */
#include <math.h>

#include "device.h"

#define J1 0.05      /* in-oz s^2/rad */
#define J2 0.01
#define C1 2.0       /* in-oz s/rad, viscous */
#define C2 0.3
#define K_FLEX 800.0 /* in-oz/rad */
#define R_COARSE 1.2 /* ohm */
#define R_FINE 4.0
#define KE_COARSE 0.23 /* V s/rad, back-EMF */
#define KE_FINE 0.11
#define AC_RANGE 0.0057595865 /* rad, the autocollimator's +-0.33 deg */

static double phi1, w1, phi2, w2;

void plant_boot(void)
{
    phi1 = w1 = phi2 = w2 = 0.0;
}

void plant_sample(sensors_t *s)
{
    s->phi1 = phi1;
    s->phi2 = phi2;
    s->base = 0.0;
    s->gyro = w2;
    /* the autocollimator only sees within its calibrated range */
    s->autocollimator = fmax(-AC_RANGE, fmin(AC_RANGE, phi2));
}

void plant_step(double u1, double u2, double dt)
{
    double flex = K_FLEX * (phi2 - phi1) + C2 * (w2 - w1);
    double a1 = (u1 - u2 - C1 * w1 + flex) / J1;
    double a2 = (u2 - flex) / J2;
    w1 += a1 * dt;
    w2 += a2 * dt;
    phi1 += w1 * dt;
    phi2 += w2 * dt;
}

/* terminal voltages R i + back-EMF */
void plant_electrics(double i1, double i2, double *v1, double *v2)
{
    *v1 = R_COARSE * i1 + KE_COARSE * w1;
    *v2 = R_FINE * i2 + KE_FINE * (w2 - w1);
}

/* slow, bounded temperature wander so the HOUSEKEEPING plots are not flat lines */
void plant_temperatures(double *coarse, double *fine, double *flexure, double *electronics)
{
    double t = (double)dev.tick / (double)HFB_CONTROL_RATE_HZ;
    *coarse = 31.0 + 0.5 * sin(t / 60.0);
    *fine = 29.0 + 0.4 * sin(t / 45.0);
    *flexure = 23.0 + 0.2 * sin(t / 90.0);
    *electronics = 38.0 + 0.3 * sin(t / 120.0);
}
