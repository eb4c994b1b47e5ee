/*
 * params.c - the parameter table of SPEC 11.1: the validation rules applied at
 * PARAM_COMMIT, and activation (decoding the table into the values the control law
 * uses, with the side effects SPEC 11.1 "What activation changes" lists).
 *
 * The kit gives each entry's offset, count and f32-rounded range as macros but no
 * table of entries to loop over, so ENTRIES below lists them once, from those macros.
 * The kit drift test keeps the macros in step with parameters.toml; a new entry in the
 * TOML still needs a line here (the table size check in main.c's self-test catches a
 * forgotten one).
 */
#include <complex.h>
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "device.h"

typedef enum { T_U8, T_F32, T_F64 } etype_t;

typedef struct {
    const char *name;
    etype_t type;
    unsigned offset, count;
    double min, max;          /* f32 bounds already rounded to float by the kit */
    int sos;                  /* filter = "sos": rule 3 applies */
} entry_t;

#define F32(NAME, name) {#name, T_F32, HFB_PARAM_##NAME##_OFFSET, HFB_PARAM_##NAME##_COUNT, \
                          (double)HFB_PARAM_##NAME##_MIN, (double)HFB_PARAM_##NAME##_MAX, 0}
#define U8(NAME, name) {#name, T_U8, HFB_PARAM_##NAME##_OFFSET, HFB_PARAM_##NAME##_COUNT, \
                         (double)HFB_PARAM_##NAME##_MIN, (double)HFB_PARAM_##NAME##_MAX, 0}
#define SOS(NAME, name) {#name, T_F64, HFB_PARAM_##NAME##_OFFSET, HFB_PARAM_##NAME##_COUNT, \
                          HFB_PARAM_##NAME##_MIN, HFB_PARAM_##NAME##_MAX, 1}

static const entry_t ENTRIES[] = {
    F32(WATCHDOG_TIMEOUT, watchdog_timeout),
    F32(SATURATION_COARSE, saturation_coarse),
    F32(SATURATION_FINE, saturation_fine),
    F32(OUTER_LOOP_GAIN, outer_loop_gain),
    F32(COMPLEMENTARY_CROSSOVER, complementary_crossover),
    U8(FRICTION_COMP_ENABLED, friction_comp_enabled),
    F32(TRAVEL_LIMIT, travel_limit),
    U8(ANTI_WINDUP, anti_windup),
    SOS(RELATIVE_C0, relative_c0),
    SOS(RELATIVE_C1, relative_c1),
    SOS(RELATIVE_C2, relative_c2),
    SOS(INERTIAL_C0, inertial_c0),
    SOS(INERTIAL_C1, inertial_c1),
    SOS(INERTIAL_C2, inertial_c2),
    U8(FRICTION_COMP_MODEL, friction_comp_model),
    F32(FRICTION_COMP_SIGMA, friction_comp_sigma),
    F32(FRICTION_COMP_COULOMB, friction_comp_coulomb),
    F32(FRICTION_COMP_ALPHA, friction_comp_alpha),
    U8(FRICTION_COMP_TABLE_POINTS, friction_comp_table_points),
    F32(FRICTION_COMP_TABLE_X, friction_comp_table_x),
    F32(FRICTION_COMP_TABLE_SLOPE, friction_comp_table_slope),
};
#define N_ENTRIES (sizeof ENTRIES / sizeof ENTRIES[0])

static const unsigned CASCADE_OFFSETS[6] = {
    HFB_PARAM_RELATIVE_C0_OFFSET, HFB_PARAM_RELATIVE_C1_OFFSET, HFB_PARAM_RELATIVE_C2_OFFSET,
    HFB_PARAM_INERTIAL_C0_OFFSET, HFB_PARAM_INERTIAL_C1_OFFSET, HFB_PARAM_INERTIAL_C2_OFFSET,
};

static size_t type_size(etype_t t)
{
    return t == T_U8 ? 1u : t == T_F32 ? 4u : 8u;
}

/* the table's byte count from ENTRIES; main.c compares it with HFB_PARAM_TABLE_SIZE */
size_t params_layout_size(void);
size_t params_layout_size(void)
{
    const entry_t *last = &ENTRIES[N_ENTRIES - 1u];
    return last->offset + last->count * type_size(last->type);
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
    /* rules 1 (finite) and 2 (range, in the entry's own type) on every element */
    for (e = 0; e < N_ENTRIES; e++) {
        const entry_t *en = &ENTRIES[e];
        for (i = 0; i < en->count; i++) {
            const uint8_t *p = t + en->offset + i * type_size(en->type);
            if (en->type == T_U8) {
                double v = (double)hfb_get_u8(p);
                if (v < en->min || v > en->max) {
                    (void)snprintf(why, cap, "%s[%u] out of range", en->name, i);
                    return -1;
                }
            } else if (en->type == T_F32) {
                float v = hfb_get_f32(p);
                if (!isfinite(v) || v < (float)en->min || v > (float)en->max) {
                    (void)snprintf(why, cap, "%s[%u] not finite or out of range", en->name, i);
                    return -1;
                }
            } else {
                double v = hfb_get_f64(p);
                if (!isfinite(v) || v < en->min || v > en->max) {
                    (void)snprintf(why, cap, "%s[%u] not finite or out of range", en->name, i);
                    return -1;
                }
            }
        }
    }
    /* rule 3: filter sections */
    for (e = 0; e < N_ENTRIES; e++) {
        const entry_t *en = &ENTRIES[e];
        if (!en->sos) {
            continue;
        }
        for (i = 0; i < en->count / 6u; i++) {
            double c[6];
            unsigned j;
            for (j = 0; j < 6u; j++) {
                c[j] = hfb_get_f64(t + en->offset + (i * 6u + j) * 8u);
            }
            if (!section_ok(c)) {
                (void)snprintf(why, cap, "%s section %u: a0 != 1 or a pole not allowed", en->name, i);
                return -1;
            }
        }
    }
    /* rule 4: the used points of the friction slope table, as the f32 values received */
    n = hfb_get_u8(t + HFB_PARAM_FRICTION_COMP_TABLE_POINTS_OFFSET);
    {
        const uint8_t *xs = t + HFB_PARAM_FRICTION_COMP_TABLE_X_OFFSET;
        const uint8_t *ss = t + HFB_PARAM_FRICTION_COMP_TABLE_SLOPE_OFFSET;
        if (n < 2u || n > HFB_PARAM_FRICTION_COMP_TABLE_X_COUNT) {
            (void)snprintf(why, cap, "friction_comp_table_points out of range");
            return -1;
        }
        if (hfb_get_f32(xs) != 0.0f || fabs((double)hfb_get_f32(xs + 4u * (n - 1u)) - 2.0) > 1e-6) {
            (void)snprintf(why, cap, "slope table: x[0] must be 0 and x[n-1] 2");
            return -1;
        }
        for (i = 0; i + 1u < n; i++) {
            if (!(hfb_get_f32(xs + 4u * (i + 1u)) > hfb_get_f32(xs + 4u * i))) {
                (void)snprintf(why, cap, "slope table: x not strictly increasing at %u", i);
                return -1;
            }
            if (!(hfb_get_f32(ss + 4u * (i + 1u)) <= hfb_get_f32(ss + 4u * i))) {
                (void)snprintf(why, cap, "slope table: slope increasing at %u", i);
                return -1;
            }
        }
    }
    return 0;
}

/* Decode a table (already valid) into dev.p and the cascades; SPEC 11.1 "What
   activation changes". */
void params_activate(const uint8_t *t, uint16_t version)
{
    int k, changed = 0;
    memcpy(dev.table, t, HFB_PARAM_TABLE_SIZE);
    dev.table_crc = hfb_crc32(dev.table, HFB_PARAM_TABLE_SIZE);
    dev.table_version = version;
    dev.p.watchdog_timeout = hfb_get_f32(t + HFB_PARAM_WATCHDOG_TIMEOUT_OFFSET);
    dev.p.saturation_coarse = hfb_get_f32(t + HFB_PARAM_SATURATION_COARSE_OFFSET);
    dev.p.saturation_fine = hfb_get_f32(t + HFB_PARAM_SATURATION_FINE_OFFSET);
    dev.p.outer_loop_gain = hfb_get_f32(t + HFB_PARAM_OUTER_LOOP_GAIN_OFFSET);
    dev.p.complementary_crossover = hfb_get_f32(t + HFB_PARAM_COMPLEMENTARY_CROSSOVER_OFFSET);
    dev.p.friction_comp_enabled = hfb_get_u8(t + HFB_PARAM_FRICTION_COMP_ENABLED_OFFSET);
    dev.p.travel_limit = hfb_get_f32(t + HFB_PARAM_TRAVEL_LIMIT_OFFSET);
    dev.p.anti_windup = hfb_get_u8(t + HFB_PARAM_ANTI_WINDUP_OFFSET);
    for (k = 0; k < 6; k++) {
        int i, j;
        for (i = 0; i < CASCADE_ROWS; i++) {
            for (j = 0; j < 6; j++) {
                double v = hfb_get_f64(t + CASCADE_OFFSETS[k] + (unsigned)(i * 6 + j) * 8u);
                if (v != dev.cascade[k].c[i][j]) {
                    changed = 1;
                }
                dev.cascade[k].c[i][j] = v;
            }
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
