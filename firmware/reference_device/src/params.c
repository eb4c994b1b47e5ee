/*
 * params.c - the parameter table of SPEC 11.1: the validation rules applied at
 * PARAM_COMMIT, and activation (decoding the table into the values the control law
 * uses, with the side effects SPEC 11.1 "What activation changes" lists).
 *
 * Rules 1-3 loop over the kit's hfb_params[] (offset, type, count, range rounded to
 * the entry's type, the sos flag), so an entry added to parameters.toml is validated
 * after a new export with no edit here.  Rule 4 and activation name the entries the
 * control law uses; they read them through their hfb_params[] entry, in the type the
 * TOML gives.
 */
#include <complex.h>
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "device.h"

/* element k of a named entry of table t, read in the entry's own type */
static double param(const uint8_t *t, uint16_t id, uint32_t k)
{
    const hfb_param_info_t *e = hfb_param_info(id);
    return hfb_value_get(e->type, t + e->offset + k * e->element_size);
}

/* The device's fixed storage must fit the kit's layout: a dictionary change that
   breaks it must stop the device at boot, not overflow dev.cascade.  (The entries the
   control law names exist, or their HFB_PARAM_*_ID macros would not compile.) */
int params_self_test(char *why, size_t cap)
{
    size_t e;
    int cascades = 0;
    for (e = 0; e < HFB_PARAM_ENTRIES; e++) {
        const hfb_param_info_t *en = &hfb_params[e];
        if (en->sos && (cascade_slot(en->id) < 0 || en->dims != 2u || en->shape[0] != CASCADE_ROWS)) {
            (void)snprintf(why, cap, "%s: not one of the device's six %d-row cascades", en->name,
                           CASCADE_ROWS);
            return -1;
        }
        cascades += en->sos ? 1 : 0;
    }
    if (cascades != 6) {
        (void)snprintf(why, cap, "%d sos entries in the kit, the control law has 6 cascades", cascades);
        return -1;
    }
    return 0;
}

/* which of dev.cascade[] an sos entry feeds: relative c0 c1 c2, inertial c0 c1 c2 */
int cascade_slot(uint16_t id)
{
    switch (id) {
    case HFB_PARAM_RELATIVE_C0_ID: return 0;
    case HFB_PARAM_RELATIVE_C1_ID: return 1;
    case HFB_PARAM_RELATIVE_C2_ID: return 2;
    case HFB_PARAM_INERTIAL_C0_ID: return 3;
    case HFB_PARAM_INERTIAL_C1_ID: return 4;
    case HFB_PARAM_INERTIAL_C2_ID: return 5;
    default: return -1;
    }
}

/* SPEC 11.1 rule 3: each root of z^2 + a1 z + a2 inside the unit circle
   (|p| <= 1 - 1e-9) or an integrator (|p - 1| <= 1e-6 and |p| <= 1 + 1e-9). */
static int pole_ok(double complex p)
{
    double m = cabs(p);
    return m <= 1.0 - 1e-9 || (cabs(p - 1.0) <= 1e-6 && m <= 1.0 + 1e-9);
}

static int section_ok(const double *c)
{
    double a1 = c[4], a2 = c[5];
    double complex d, p1, p2;
    if (c[3] != 1.0) {
        return 0;                          /* a0 must be 1 exactly: no normalising */
    }
    if (a1 == 0.0 && a2 == 0.0) {
        return 1;                          /* no poles: FIR or identity */
    }
    d = csqrt((double complex)(a1 * a1 - 4.0 * a2));
    p1 = (-a1 + d) / 2.0;
    p2 = (-a1 - d) / 2.0;
    return pole_ok(p1) && pole_ok(p2);
}

int params_validate(const uint8_t *t, char *why, size_t cap)
{
    size_t e;
    unsigned i, n;
    /* rules 1 (finite) and 2 (range, compared in the entry's own type) on every element,
       used or not */
    for (e = 0; e < HFB_PARAM_ENTRIES; e++) {
        const hfb_param_info_t *en = &hfb_params[e];
        for (i = 0; i < en->count; i++) {
            if (!hfb_value_in_range(en->type, t + en->offset + i * en->element_size, en->min, en->max)) {
                (void)snprintf(why, cap, "%s[%u] not finite or out of range", en->name, i);
                return -1;
            }
        }
    }
    /* rule 3: each row b0 b1 b2 a0 a1 a2 of every filter = "sos" entry, in double */
    for (e = 0; e < HFB_PARAM_ENTRIES; e++) {
        const hfb_param_info_t *en = &hfb_params[e];
        if (!en->sos) {
            continue;
        }
        for (i = 0; i < en->count / 6u; i++) {
            double c[6];
            unsigned j;
            for (j = 0; j < 6u; j++) {
                c[j] = hfb_value_get(en->type, t + en->offset + (i * 6u + j) * en->element_size);
            }
            if (!section_ok(c)) {
                (void)snprintf(why, cap, "%s section %u: a0 != 1 or a pole not allowed", en->name, i);
                return -1;
            }
        }
    }
    /* rule 4: the used points of the friction slope table, as the values received */
    n = (unsigned)param(t, HFB_PARAM_FRICTION_COMP_TABLE_POINTS_ID, 0);
    if (n < 2u || n > hfb_param_info(HFB_PARAM_FRICTION_COMP_TABLE_X_ID)->count
        || n > hfb_param_info(HFB_PARAM_FRICTION_COMP_TABLE_SLOPE_ID)->count) {
        (void)snprintf(why, cap, "friction_comp_table_points out of range");
        return -1;
    }
    if (param(t, HFB_PARAM_FRICTION_COMP_TABLE_X_ID, 0) != 0.0
        || fabs(param(t, HFB_PARAM_FRICTION_COMP_TABLE_X_ID, n - 1u) - 2.0) > 1e-6) {
        (void)snprintf(why, cap, "slope table: x[0] must be 0 and x[n-1] 2");
        return -1;
    }
    for (i = 0; i + 1u < n; i++) {
        if (!(param(t, HFB_PARAM_FRICTION_COMP_TABLE_X_ID, i + 1u) > param(t, HFB_PARAM_FRICTION_COMP_TABLE_X_ID, i))) {
            (void)snprintf(why, cap, "slope table: x not strictly increasing at %u", i);
            return -1;
        }
        if (!(param(t, HFB_PARAM_FRICTION_COMP_TABLE_SLOPE_ID, i + 1u)
              <= param(t, HFB_PARAM_FRICTION_COMP_TABLE_SLOPE_ID, i))) {
            (void)snprintf(why, cap, "slope table: slope increasing at %u", i);
            return -1;
        }
    }
    return 0;
}

/* Decode a table (already valid) into dev.p and the cascades; SPEC 11.1 "What
   activation changes". */
void params_activate(const uint8_t *t, uint16_t version)
{
    size_t e;
    int changed = 0;
    memcpy(dev.table, t, HFB_PARAM_TABLE_SIZE);
    dev.table_crc = hfb_crc32(dev.table, HFB_PARAM_TABLE_SIZE);
    dev.table_version = version;
    dev.p.watchdog_timeout = (float)param(t, HFB_PARAM_WATCHDOG_TIMEOUT_ID, 0);
    dev.p.saturation_coarse = (float)param(t, HFB_PARAM_SATURATION_COARSE_ID, 0);
    dev.p.saturation_fine = (float)param(t, HFB_PARAM_SATURATION_FINE_ID, 0);
    dev.p.outer_loop_gain = (float)param(t, HFB_PARAM_OUTER_LOOP_GAIN_ID, 0);
    dev.p.complementary_crossover = (float)param(t, HFB_PARAM_COMPLEMENTARY_CROSSOVER_ID, 0);
    dev.p.friction_comp_enabled = (uint8_t)param(t, HFB_PARAM_FRICTION_COMP_ENABLED_ID, 0);
    dev.p.travel_limit = (float)param(t, HFB_PARAM_TRAVEL_LIMIT_ID, 0);
    dev.p.anti_windup = (uint8_t)param(t, HFB_PARAM_ANTI_WINDUP_ID, 0);
    /* the cascades: every sos entry, into its slot (params_self_test checked the shape) */
    for (e = 0; e < HFB_PARAM_ENTRIES; e++) {
        const hfb_param_info_t *en = &hfb_params[e];
        cascade_t *k;
        uint32_t i;
        if (!en->sos) {
            continue;
        }
        k = &dev.cascade[cascade_slot(en->id)];
        for (i = 0; i < en->count; i++) {
            double v = hfb_value_get(en->type, t + en->offset + i * en->element_size);
            if (v != k->c[i / 6u][i % 6u]) {
                changed = 1;
            }
            k->c[i / 6u][i % 6u] = v;
        }
    }
    /* any cascade changed: all six restart from zero; none changed: states carry on */
    if (changed) {
        control_reset_cascades();
    }
    /* the table sets the run-time switch (FRICTION_COMP changes it afterwards) */
    dev.friction_comp_on = dev.p.friction_comp_enabled;
    /* the LOS estimate keeps its value; the friction compensator restarts */
    friction_reset();
}

void params_boot(void)
{
    memset(dev.cascade, 0, sizeof dev.cascade);
    params_activate(hfb_param_default_table, 0u);   /* version 0, SPEC 11.1 */
    control_reset_cascades();
}
