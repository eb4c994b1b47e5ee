/*
 * main.c - command line, boot, and the single-threaded loop.
 *
 * One loop, no threads: at every control period it
 *   1. reads every socket without blocking and executes the commands found (they all
 *      finish at once, between two periods - the cycle boundary of SPEC 11.1),
 *   2. runs the control periods that are due (normally one; after a stall, the missed
 *      ones back to back, so the tick keeps counting real periods, SPEC 2),
 *   3. sleeps with clock_nanosleep on CLOCK_MONOTONIC until the next period's absolute
 *      deadline, so the rate does not drift with the loop's own run time.
 * Deterministic and simple; commands wait at most one period (0.83 ms) to be read.
 */
#define _POSIX_C_SOURCE 200809L

#include <errno.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "device.h"

device_t dev;

static volatile sig_atomic_t stop_requested;

static void on_signal(int sig)
{
    (void)sig;
    stop_requested = 1;
}

static const struct {
    const char *name;
    unsigned flag;
} DEVIATIONS[] = {
    {"crc-range", DEV_CRC_RANGE},
    {"retry-twice", DEV_RETRY_TWICE},
    {"watchdog-x2", DEV_WATCHDOG_X2},
    {"commit-no-crc", DEV_COMMIT_NO_CRC},
    {"profile-late", DEV_PROFILE_LATE},
    {"foreign-host", DEV_FOREIGN_HOST},
    {"shared-history", DEV_SHARED_HISTORY},
};
#define N_DEVIATIONS (sizeof DEVIATIONS / sizeof DEVIATIONS[0])

static void usage(FILE *f)
{
    size_t i;
    fprintf(f, "usage: hfb_reference_device [--host 127.0.0.1] [--port 0] [--deviate NAME]...\n"
               "deviations (deliberate protocol errors for conformance tests):");
    for (i = 0; i < N_DEVIATIONS; i++) {
        fprintf(f, " %s", DEVIATIONS[i].name);
    }
    fprintf(f, "\n");
}

static void timespec_add_ns(struct timespec *t, long ns)
{
    t->tv_nsec += ns;
    while (t->tv_nsec >= 1000000000L) {
        t->tv_nsec -= 1000000000L;
        t->tv_sec++;
    }
}

static int before(const struct timespec *a, const struct timespec *b)
{
    return a->tv_sec < b->tv_sec || (a->tv_sec == b->tv_sec && a->tv_nsec < b->tv_nsec);
}

/* checks that cost nothing and catch a kit or a build gone wrong before a host does */
static int self_test(void)
{
    static const uint8_t check[] = "123456789";
    if (hfb_crc32(check, 9u) != HFB_CRC_CHECK) {
        fprintf(stderr, "self-test: CRC check value wrong\n");
        return -1;
    }
    if (hfb_crc32(hfb_param_default_table, HFB_PARAM_TABLE_SIZE) != HFB_PARAM_DEFAULT_TABLE_CRC) {
        fprintf(stderr, "self-test: default parameter table CRC wrong\n");
        return -1;
    }
    {
        char why[200];
        if (params_self_test(why, sizeof why) != 0) {
            fprintf(stderr, "self-test: the kit's parameter entries do not fit the device: %s\n", why);
            return -1;
        }
        if (params_validate(hfb_param_default_table, why, sizeof why) != 0) {
            fprintf(stderr, "self-test: the default table fails validation: %s\n", why);
            return -1;
        }
    }
    return 0;
}

int main(int argc, char **argv)
{
    const char *host = "127.0.0.1";
    long port = 0;
    int i;
    struct sigaction sa;
    struct timespec next;
    const long period_ns = 1000000000L / (long)HFB_CONTROL_RATE_HZ;

    memset(&dev, 0, sizeof dev);
    for (i = 1; i < argc; i++) {
        if (strcmp(argv[i], "--host") == 0 && i + 1 < argc) {
            host = argv[++i];
        } else if (strcmp(argv[i], "--port") == 0 && i + 1 < argc) {
            char *end;
            port = strtol(argv[++i], &end, 10);
            if (*end != '\0' || port < 0 || port > 65535) {
                fprintf(stderr, "hfb_reference_device: --port must be 0 ... 65535\n");
                return 2;
            }
        } else if (strcmp(argv[i], "--deviate") == 0 && i + 1 < argc) {
            size_t k;
            const char *name = argv[++i];
            for (k = 0; k < N_DEVIATIONS && strcmp(DEVIATIONS[k].name, name) != 0; k++) {
            }
            if (k == N_DEVIATIONS) {
                fprintf(stderr, "hfb_reference_device: unknown deviation '%s'\n", name);
                usage(stderr);
                return 2;
            }
            dev.deviations |= DEVIATIONS[k].flag;
        } else if (strcmp(argv[i], "--help") == 0 || strcmp(argv[i], "-h") == 0) {
            usage(stdout);
            return 0;
        } else {
            fprintf(stderr, "hfb_reference_device: unexpected argument '%s'\n", argv[i]);
            usage(stderr);
            return 2;
        }
    }
    if (self_test() != 0) {
        return 1;
    }

    /* boot (SPEC 10): IDLE, disarmed, no fault, default table version 0, no session */
    dev.owner = -1;
    dev.listen_fd = dev.udp_fd = -1;
    dev.mode = HFB_PKT_HIGH_RATE_MODE_IDLE;
    dev.watchdog_state = HFB_PKT_HOUSEKEEPING_WATCHDOG_NO_SESSION;
    /* any starting value is allowed (SPEC 2); random ones show a host that assumes 0 */
    dev.seq_high_rate = random_token();
    dev.seq_housekeeping = random_token();
    dev.seq_event = random_token();
    dev.seq_response = random_token();
    plant_boot();
    params_boot();

    memset(&sa, 0, sizeof sa);
    sa.sa_handler = on_signal;
    sigemptyset(&sa.sa_mask);
    (void)sigaction(SIGTERM, &sa, NULL);
    (void)sigaction(SIGINT, &sa, NULL);
    signal(SIGPIPE, SIG_IGN);                 /* a vanished host is an error return, not death */

    if (net_open(host, (uint16_t)port) != 0) {
        return 1;
    }
    printf("listening tcp://%s:%u\n", host, (unsigned)dev.local_port);
    fflush(stdout);
    event_send(HFB_PKT_EVENT_LEVEL_INFO, HFB_EVT_BOOT, "booted");   /* nobody hears it: no session */

    clock_gettime(CLOCK_MONOTONIC, &next);
    while (!stop_requested) {
        struct timespec now;
        int ran = 0;
        net_poll();
        clock_gettime(CLOCK_MONOTONIC, &now);
        while (!before(&now, &next) && ran < (int)HFB_CONTROL_RATE_HZ) {
            control_period();
            timespec_add_ns(&next, period_ns);
            ran++;
        }
        if (ran == (int)HFB_CONTROL_RATE_HZ) {
            /* more than a second behind (the process was stopped): start afresh from now
               rather than bursting on; the periods skipped are not counted as ticks */
            clock_gettime(CLOCK_MONOTONIC, &next);
        }
        net_poll();                           /* flush what the periods queued */
        while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &next, NULL) == EINTR && !stop_requested) {
        }
    }

    /* SIGTERM/SIGINT: disarm first (motors to zero), then close */
    if (dev.armed) {
        control_disarm("device shutting down", 1);
    }
    net_poll();
    net_close_all();
    free(dev.param_staging);
    free(dev.profile_staging);
    free(dev.profile);
    return 0;
}
