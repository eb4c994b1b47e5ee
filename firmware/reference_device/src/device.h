/*
 * device.h - the state of the C reference device and the functions each file offers.
 *
 * The device is single-threaded: main.c runs one loop that reads the sockets, executes
 * the commands that arrived and then runs the control periods that are due.  So all
 * state lives in one struct, `dev`, and no locking is needed anywhere.
 */
#ifndef REFDEV_DEVICE_H
#define REFDEV_DEVICE_H

#include <stddef.h>
#include <stdint.h>

#include "hfb_protocol.h"

#define FIRMWARE_VERSION 0x000100u          /* 0.1.0: major<<16 | minor<<8 | patch */
#define MAX_CONNECTIONS 4                   /* SPEC 1.1: at least two at once; more are closed */
#define HISTORY_SIZE 64                     /* SPEC 6.4: the last 64 commands answered */
#define CONTROL_PERIOD_S (1.0 / (double)HFB_CONTROL_RATE_HZ)
#define HOUSEKEEPING_EVERY_TICKS 120u       /* SPEC 5: 10 Hz at 1200 Hz */
#define CASCADE_ROWS 12                     /* parameters.toml: shape [12, 6] */

/* rig constants of the stand-in (SPEC 10.1 "rig constants"; plant.c explains them) */
#define PEAK_TORQUE_COARSE 81.3             /* in-oz, P1 */
#define PEAK_TORQUE_FINE 16.1               /* in-oz, P2 */
/* Kt1, Kt2: SPEC 10.1 makes them rig constants built into the device (no command reads
   them); these are the 2-DOF rigs' values (profiles/testbeds, torque_constant) */
#define TORQUE_CONSTANT_COARSE 32.1         /* in-oz/A, Kt1 */
#define TORQUE_CONSTANT_FINE 16.1           /* in-oz/A, Kt2 */
#define FLEXURE_SAFE_DEFLECTION 0.015       /* rad, SPEC 9.2 (2-DOF rigs of today) */
#define GYRO_FULL_SCALE 17.453              /* rad/s, SPEC 11.2 */

/* ---- deliberate deviations for the conformance suite (--deviate NAME) ------------- */
enum {
    DEV_CRC_RANGE = 1u << 0,      /* frames sent with the CRC over one byte too few */
    DEV_RETRY_TWICE = 1u << 1,    /* a retried command is executed again */
    DEV_WATCHDOG_X2 = 1u << 2,    /* the watchdog waits twice the table's timeout */
    DEV_COMMIT_NO_CRC = 1u << 3,  /* PARAM_COMMIT ignores the CRC */
    DEV_PROFILE_LATE = 1u << 4,   /* a profile plays one sample late */
    DEV_FOREIGN_HOST = 1u << 5,   /* a second host's CONNECT wins without take_over */
    DEV_SHARED_HISTORY = 1u << 6  /* one retry history for all connections */
};

/* ---- one second-order-section cascade (SPEC 10.1, direct form II transposed) ------ */
typedef struct {
    double c[CASCADE_ROWS][6];    /* b0 b1 b2 a0 a1 a2 per row */
    double s[CASCADE_ROWS][2];    /* the two states of each section */
} cascade_t;

/* ---- the active parameter table, decoded (params.c) -------------------------------- */
typedef struct {
    float watchdog_timeout, saturation_coarse, saturation_fine, outer_loop_gain;
    float complementary_crossover, travel_limit;
    uint8_t friction_comp_enabled, anti_windup;
} params_t;

/* ---- a TCP command connection (net.c) ----------------------------------------------- */
typedef struct {
    int fd;                       /* -1: slot free */
    uint32_t serial;              /* this connection's number: slots are reused, these not */
    uint32_t peer_ip;             /* network byte order */
    uint16_t peer_port;           /* host byte order */
    hfb_deframer_t rx;
    size_t out_len;               /* bytes waiting in out[] (send buffer) */
    uint8_t out[65536];
} connection_t;

/* ---- one remembered command with the RESPONSE payloads sent for it (SPEC 6.4) ------ */
typedef struct {
    int used;
    uint32_t connection;          /* the serial of the connection it came on (SPEC 6.4) */
    uint32_t sequence;
    uint16_t opcode;
    int n;                        /* payloads recorded: 1 (REJECTED) or 2 */
    size_t len[2];
    uint8_t payload[2][HFB_MAX_PAYLOAD];
} history_entry_t;

typedef struct {
    /* configuration */
    unsigned deviations;
    int running;

    /* time */
    uint32_t tick;                /* the last control period run */

    /* network */
    int listen_fd, udp_fd;
    uint32_t local_ip;            /* network byte order */
    uint16_t local_port;
    connection_t conn[MAX_CONNECTIONS];

    /* session (SPEC 7) */
    uint32_t token;               /* 0: no session */
    int owner;                    /* index into conn[], -1 without a session */
    uint32_t owner_since_tick;
    uint16_t telemetry_port;      /* 0: telemetry on the owner's TCP connection */
    uint32_t watchdog_reset_tick; /* SPEC 9.1 */
    uint8_t watchdog_state;       /* HOUSEKEEPING watchdog */
    uint16_t fault_code;          /* HOUSEKEEPING fault_code, first latched */

    /* sequence counters, one per packet the device sends (SPEC 2) */
    uint32_t seq_high_rate, seq_housekeeping, seq_event, seq_response;
    uint32_t commands_accepted, commands_rejected, telemetry_overruns;

    /* retries (SPEC 6.4): a ring of the last HISTORY_SIZE commands */
    history_entry_t history[HISTORY_SIZE];
    int history_next;
    uint32_t next_connection_serial;

    /* modes and control (SPEC 10) */
    uint8_t mode;
    int armed;
    int friction_comp_on;
    double reference, rate_reference, current_cmd_coarse, current_cmd_fine;
    double los_estimate;
    double last_phi1;             /* the friction compensator's input is its increment */
    int have_last_phi1;
    cascade_t cascade[6];         /* relative c0 c1 c2, inertial c0 c1 c2 */

    /* parameter table (SPEC 11.1) */
    uint8_t table[HFB_PARAM_TABLE_SIZE];
    uint32_t table_crc;
    uint16_t table_version;
    params_t p;
    uint8_t *param_staging;       /* NULL: nothing staged */
    uint32_t param_staging_length;
    uint16_t param_staging_version;

    /* profiles (SPEC 11.2) */
    uint8_t *profile_staging;     /* big-endian f32 samples as received */
    uint32_t profile_staging_count;
    uint16_t profile_staging_id;
    uint8_t profile_staging_target;
    uint8_t *profile;             /* the committed profile, NULL if none */
    uint32_t profile_count;
    uint16_t profile_id;
    uint8_t profile_target;
    int profile_playing;
    uint32_t profile_next;        /* index of the next sample to play */
    uint32_t profile_delay;       /* periods still to wait (--deviate profile-late) */
    uint32_t profile_index_shown; /* HIGH_RATE profile_index of this period */
} device_t;

extern device_t dev;

/* net.c: sockets, buffered TCP output, telemetry transport */
int net_open(const char *host, uint16_t port);
void net_poll(void);                        /* accept, read, flush; never blocks */
void net_close_all(void);
int net_send_tcp(int c, const uint8_t *frame, size_t n);   /* 0: queued, -1: no room */
int net_send_telemetry(const uint8_t *frame, size_t n);    /* 0: sent, -1: not sent */
void net_drop_connection(int c);

/* telemetry.c: frame encoding (the kit's encoder plus --deviate crc-range) */
size_t frame_build(uint8_t *frame, uint8_t packet_id, uint32_t sequence, const uint8_t *payload,
                   size_t payload_len);

/* telemetry.c: HIGH_RATE, HOUSEKEEPING, EVENT */
typedef struct {
    double phi1, phi2, base, gyro, autocollimator;
    double error_angle, error_rate, u1, u2, t_fc;
    double current_coarse, current_fine, voltage_coarse, voltage_fine;
    int coarse_saturated, fine_saturated;
} period_record_t;
void telemetry_high_rate(const period_record_t *r);
void telemetry_housekeeping(void);
void event_send(uint8_t level, uint16_t code, const char *text);

/* session.c (SPEC 7, 9.1) */
void session_connect(int c, uint32_t sequence, uint16_t opcode, const uint8_t *args, size_t n);
void session_refuse_dictionary(int c, uint32_t sequence, uint16_t opcode);
void session_end(const char *why);
void session_connection_closed(int c);
void session_owner_text(char *out, size_t cap);
uint32_t random_token(void);

/* commands.c (SPEC 6) */
void commands_on_frame(void *context, const uint8_t *frame, size_t length);
void commands_on_other_version(void *context, const uint8_t *frame, size_t length);
void respond(int c, uint32_t sequence, uint16_t opcode, uint8_t stage, uint16_t reason,
             const uint8_t *data, size_t n);

/* control.c (SPEC 9, 10) */
void control_period(void);
void control_disarm(const char *why, int send_event);
void control_arm(void);
void control_set_mode(uint8_t mode);
void control_safe_state(void);
void control_reset_cascades(void);

/* params.c (SPEC 11.1) */
void params_boot(void);
int params_self_test(char *why, size_t cap);
int cascade_slot(uint16_t param_id);        /* dev.cascade[] of an sos entry, -1: none */
int params_validate(const uint8_t *table, char *why, size_t cap);
void params_activate(const uint8_t *table, uint16_t version);

/* profile.c (SPEC 11.2) */
int profile_sample_valid(uint8_t target, float v);
int profile_target_plays_in_mode(uint8_t target, uint8_t mode);
void profile_start(void);
void profile_stop(int send_event);
void profile_step(void);                    /* once per period, SPEC 10.1 step 4 */

/* friction.c: the friction compensator (SPEC 10.1 step 5) */
void friction_reset(void);
double friction_step(double dphi);

/* plant.c: the stand-in plant */
typedef struct {
    double phi1, phi2, base, gyro, autocollimator;
} sensors_t;
void plant_boot(void);
void plant_sample(sensors_t *s);
void plant_step(double u1, double u2, double dt);
void plant_electrics(double i1, double i2, double *v1, double *v2);
void plant_temperatures(double *coarse, double *fine, double *flexure, double *electronics);

#endif
