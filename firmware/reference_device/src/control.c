/*
 * control.c - one control period (SPEC 10.1, in its order), the watchdog (SPEC 9.1),
 * faults (SPEC 9.2), and the arm/disarm/mode transitions (SPEC 10).
 * The friction compensator itself (step 5) is friction.c.
 */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "device.h"

#define TWO_PI 6.283185307179586

enum { REL_C0, REL_C1, REL_C2, INE_C0, INE_C1, INE_C2 };

void control_reset_cascades(void)
{
    int k;
    for (k = 0; k < 6; k++) {
        memset(dev.cascade[k].s, 0, sizeof dev.cascade[k].s);
    }
}

/* Run a cascade on x in direct form II transposed (SPEC 10.1), all rows in order.  The
   new states go to `next`; the caller keeps or drops them (conditional integration). */
static double cascade_run(const cascade_t *f, double x, double next[CASCADE_ROWS][2])
{
    int i;
    for (i = 0; i < CASCADE_ROWS; i++) {
        const double *c = f->c[i];
        double y = c[0] * x + f->s[i][0];
        next[i][0] = c[1] * x - c[4] * y + f->s[i][1];
        next[i][1] = c[2] * x - c[5] * y;
        x = y;
    }
    return x;
}

void control_set_mode(uint8_t mode)
{
    if (mode != dev.mode) {
        static const char *const names[] = {"IDLE", "OPEN_LOOP", "RELATIVE", "INERTIAL"};
        char text[64];
        dev.mode = mode;
        (void)snprintf(text, sizeof text, "mode %s", names[mode & 3u]);
        event_send(HFB_PKT_EVENT_LEVEL_INFO, HFB_EVT_MODE_CHANGED, text);
    }
}

/* SPEC 10: ARM holds the position the mode controls, zeroes the open-loop commands and
   the rate reference, and restarts the six cascades. */
void control_arm(void)
{
    sensors_t s;
    plant_sample(&s);
    if (dev.mode == HFB_PKT_HIGH_RATE_MODE_RELATIVE) {
        dev.reference = s.phi2;
    } else if (dev.mode == HFB_PKT_HIGH_RATE_MODE_INERTIAL) {
        dev.reference = dev.los_estimate;
    }
    dev.current_cmd_coarse = 0.0;
    dev.current_cmd_fine = 0.0;
    dev.rate_reference = 0.0;
    control_reset_cascades();
    dev.armed = 1;
    event_send(HFB_PKT_EVENT_LEVEL_INFO, HFB_EVT_ARMED, "drives enabled");
}

/* Drives off, motors to zero (the next period computes no torque), profile stopped;
   the mode is left to the caller (DISARM keeps it). */
void control_disarm(const char *why, int send_event)
{
    char text[96];
    dev.armed = 0;
    dev.current_cmd_coarse = 0.0;
    dev.current_cmd_fine = 0.0;
    profile_stop(0);
    if (send_event) {
        (void)snprintf(text, sizeof text, "drives disabled: %s", why);
        event_send(HFB_PKT_EVENT_LEVEL_INFO, HFB_EVT_DISARMED, text);
    }
}

/* SPEC 7: the safe state before a new session replaces an open one */
void control_safe_state(void)
{
    if (dev.armed) {
        control_disarm("session replaced", 1);
    }
    profile_stop(0);
    control_set_mode(HFB_PKT_HIGH_RATE_MODE_IDLE);
}

/* SPEC 9.1 / 9.2: the reaction to the watchdog or a fault, in the period that detects it */
static void trip(uint16_t fault, uint16_t event, uint8_t level, const char *text)
{
    control_disarm(text, 1);
    control_set_mode(HFB_PKT_HIGH_RATE_MODE_IDLE);
    if (dev.fault_code == HFB_PKT_HOUSEKEEPING_FAULT_CODE_NONE) {
        dev.fault_code = fault;                   /* the first fault since the acknowledgement */
    }
    event_send(level, event, text);
}

void control_period(void)
{
    period_record_t r;
    sensors_t s;
    double u1 = 0.0, u2 = 0.0, t_fc;
    double limit_ticks;
    double timeout = (double)dev.p.watchdog_timeout;

    dev.tick++;
    memset(&r, 0, sizeof r);

    /* 1. sensors */
    plant_sample(&s);

    /* 2. LOS estimate: the stand-in has a gyro and an autocollimator (the inertial
          set-up), so the complementary filter runs, armed or not */
    {
        double tau = 1.0 / (TWO_PI * (double)dev.p.complementary_crossover);
        double alpha = tau / (tau + CONTROL_PERIOD_S);
        dev.los_estimate = alpha * (dev.los_estimate + s.gyro * CONTROL_PERIOD_S)
                           + (1.0 - alpha) * s.autocollimator;
    }

    /* 3. watchdog: the first period with more than timeout x 1200 ticks since the reset */
    if (dev.deviations & DEV_WATCHDOG_X2) {
        timeout *= 2.0;
    }
    /* compared in double, not rounded to whole ticks: f32 0.7 s is 839.99998 ticks, so
       the 840th period since the reset is already "more than" it */
    limit_ticks = (double)HFB_CONTROL_RATE_HZ * timeout;
    if (dev.armed && dev.token != 0u && (double)(uint32_t)(dev.tick - dev.watchdog_reset_tick) > limit_ticks) {
        dev.watchdog_state = HFB_PKT_HOUSEKEEPING_WATCHDOG_EXPIRED;
        trip(HFB_PKT_HOUSEKEEPING_FAULT_CODE_WATCHDOG, HFB_EVT_WATCHDOG_EXPIRED,
             HFB_PKT_EVENT_LEVEL_CRITICAL, "watchdog expired: no heartbeat from the session owner");
    }

    /* 4. profile */
    profile_step();

    /* 5. friction compensator, every period, armed or not; its input is the outer
          axis's increment (0 in the first period after boot) */
    t_fc = friction_step(dev.have_last_phi1 ? s.phi1 - dev.last_phi1 : 0.0);
    dev.last_phi1 = s.phi1;
    dev.have_last_phi1 = 1;

    /* 6. control law, only while armed */
    if (dev.armed) {
        if (dev.mode == HFB_PKT_HIGH_RATE_MODE_OPEN_LOOP) {
            u1 = TORQUE_CONSTANT_COARSE * dev.current_cmd_coarse;
            u2 = TORQUE_CONSTANT_FINE * dev.current_cmd_fine;
        } else if (dev.mode == HFB_PKT_HIGH_RATE_MODE_RELATIVE || dev.mode == HFB_PKT_HIGH_RATE_MODE_INERTIAL) {
            int base = dev.mode == HFB_PKT_HIGH_RATE_MODE_RELATIVE ? REL_C0 : INE_C0;
            double n0[CASCADE_ROWS][2], n1[CASCADE_ROWS][2], n2[CASCADE_ROWS][2];
            double e, v, l1, l2;
            if (dev.mode == HFB_PKT_HIGH_RATE_MODE_RELATIVE) {
                r.error_angle = dev.reference - s.phi2;
                e = r.error_angle;
            } else {
                double omega_c;
                r.error_angle = dev.reference - dev.los_estimate;
                omega_c = (double)dev.p.outer_loop_gain * r.error_angle + dev.rate_reference;
                r.error_rate = omega_c - s.gyro;
                e = r.error_rate;
            }
            v = cascade_run(&dev.cascade[base + 0], e, n0);
            u1 = cascade_run(&dev.cascade[base + 1], v, n1);
            u2 = cascade_run(&dev.cascade[base + 2], v, n2);
            if (dev.friction_comp_on) {
                u1 += t_fc;                       /* feedback modes only, never OPEN_LOOP */
            }

            /* 7. saturation and conditional integration */
            l1 = fmin((double)dev.p.saturation_coarse, PEAK_TORQUE_COARSE);
            l2 = fmin((double)dev.p.saturation_fine, PEAK_TORQUE_FINE);
            r.coarse_saturated = fabs(u1) > l1;
            r.fine_saturated = fabs(u2) > l2;
            if (!dev.p.anti_windup || !(r.coarse_saturated || r.fine_saturated)) {
                memcpy(dev.cascade[base + 0].s, n0, sizeof n0);
                memcpy(dev.cascade[base + 1].s, n1, sizeof n1);
                memcpy(dev.cascade[base + 2].s, n2, sizeof n2);
            }
        }
        /* the limits hold in every mode (OPEN_LOOP currents are bounded by their
           argument ranges, which give at most the peak torques) */
        {
            double l1 = fmin((double)dev.p.saturation_coarse, PEAK_TORQUE_COARSE);
            double l2 = fmin((double)dev.p.saturation_fine, PEAK_TORQUE_FINE);
            if (dev.mode == HFB_PKT_HIGH_RATE_MODE_OPEN_LOOP) {
                r.coarse_saturated = fabs(u1) > l1;
                r.fine_saturated = fabs(u2) > l2;
            }
            u1 = fmax(-l1, fmin(l1, u1));
            u2 = fmax(-l2, fmin(l2, u2));
        }

        /* 8. faults, only while armed: over-travel first, then the flexure */
        if (fabs(s.phi1) > (double)dev.p.travel_limit) {
            u1 = u2 = 0.0;
            trip(HFB_PKT_HOUSEKEEPING_FAULT_CODE_OVER_TRAVEL, HFB_EVT_FAULT, HFB_PKT_EVENT_LEVEL_ERROR,
                 "fault OVER_TRAVEL: |encoder_outer| beyond travel_limit");
        } else if (fabs(s.phi2 - s.phi1) > FLEXURE_SAFE_DEFLECTION) {
            u1 = u2 = 0.0;
            trip(HFB_PKT_HOUSEKEEPING_FAULT_CODE_FLEXURE_OVERDEFLECTION, HFB_EVT_FAULT,
                 HFB_PKT_EVENT_LEVEL_ERROR, "fault FLEXURE_OVERDEFLECTION: |inner - outer| beyond 0.015 rad");
        }
    }

    /* 9. outputs: currents u/Kt held over the period; the plant moves under them */
    r.phi1 = s.phi1;
    r.phi2 = s.phi2;
    r.base = s.base;
    r.gyro = s.gyro;
    r.autocollimator = s.autocollimator;
    r.u1 = u1;
    r.u2 = u2;
    r.t_fc = (dev.armed && dev.friction_comp_on) ? t_fc : 0.0;
    r.current_coarse = u1 / TORQUE_CONSTANT_COARSE;
    r.current_fine = u2 / TORQUE_CONSTANT_FINE;
    plant_electrics(r.current_coarse, r.current_fine, &r.voltage_coarse, &r.voltage_fine);
    plant_step(u1, u2, CONTROL_PERIOD_S);

    telemetry_high_rate(&r);
    if (dev.tick % HOUSEKEEPING_EVERY_TICKS == 0u) {
        telemetry_housekeeping();
    }
}
