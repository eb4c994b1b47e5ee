/*
 * session.c - SPEC 7 (session: CONNECT, take-over, end of session) and the start of the
 * watchdog count (SPEC 9.1).
 *
 * CONNECT reaches this file only after the generic checks of SPEC 6.3 (opcode, length,
 * argument ranges); the decision order here is SPEC 7's: DICTIONARY_MISMATCH, then
 * SESSION_BUSY, then a fresh session.
 */
#define _POSIX_C_SOURCE 200809L

#include <arpa/inet.h>
#include <fcntl.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#include "device.h"

/* SPEC 7: tokens must come from a cryptographic source, never a seeded generator. */
uint32_t random_token(void)
{
    uint32_t v = 0;
    int fd = open("/dev/urandom", O_RDONLY);
    if (fd >= 0) {
        uint8_t b[4];
        if (read(fd, b, sizeof b) == (ssize_t)sizeof b) {
            v = hfb_get_u32(b);
        }
        close(fd);
    }
    if (v == 0u) {
        /* no urandom (not on this Linux host): refuse to run rather than hand out a
           guessable token */
        fprintf(stderr, "hfb_reference_device: no random source for the session token\n");
        exit(1);
    }
    return v;
}

void session_owner_text(char *out, size_t cap)
{
    if (dev.token == 0u || dev.owner < 0) {
        (void)snprintf(out, cap, "no session open");
        return;
    }
    {
        struct in_addr a;
        char ip[INET_ADDRSTRLEN];
        a.s_addr = dev.conn[dev.owner].peer_ip;
        if (inet_ntop(AF_INET, &a, ip, sizeof ip) == NULL) {
            (void)snprintf(ip, sizeof ip, "?");
        }
        (void)snprintf(out, cap, "owner %s:%u since tick %lu", ip,
                       (unsigned)dev.conn[dev.owner].peer_port, (unsigned long)dev.owner_since_tick);
    }
}

/* REJECTED DICTIONARY_MISMATCH: the CONNECT reply layout with token 0 as data, so the
   host can name both versions and both hashes (SPEC 7) */
void session_refuse_dictionary(int c, uint32_t sequence, uint16_t opcode)
{
    hfb_cmd_connect_reply_t reply;
    uint8_t data[HFB_CMD_CONNECT_REPLY_SIZE];
    reply.session_token = 0u;
    reply.protocol_major = HFB_PROTOCOL_VERSION_MAJOR;
    reply.protocol_minor = HFB_PROTOCOL_VERSION_MINOR;
    reply.dictionary_hash = HFB_DICTIONARY_HASH;
    reply.tick = dev.tick;
    (void)hfb_cmd_connect_reply_pack(&reply, data, sizeof data);
    respond(c, sequence, opcode, HFB_PKT_RESPONSE_STAGE_REJECTED, HFB_ERR_DICTIONARY_MISMATCH,
            data, sizeof data);
}

void session_connect(int c, uint32_t sequence, uint16_t opcode, const uint8_t *args, size_t n)
{
    hfb_cmd_connect_args_t a;
    hfb_cmd_connect_reply_t reply;
    uint8_t data[HFB_CMD_CONNECT_REPLY_SIZE];
    int was_open = dev.token != 0u;

    (void)hfb_cmd_connect_args_unpack(&a, args, n);
    reply.protocol_major = HFB_PROTOCOL_VERSION_MAJOR;
    reply.protocol_minor = HFB_PROTOCOL_VERSION_MINOR;
    reply.dictionary_hash = HFB_DICTIONARY_HASH;

    /* 1: the dictionary */
    if (a.protocol_major != HFB_PROTOCOL_VERSION_MAJOR || a.dictionary_hash != HFB_DICTIONARY_HASH) {
        session_refuse_dictionary(c, sequence, opcode);
        return;
    }
    /* 2: another connection owns the session.  The owner's own CONNECT is never busy. */
    if (was_open && c != dev.owner && !a.take_over && !(dev.deviations & DEV_FOREIGN_HOST)) {
        respond(c, sequence, opcode, HFB_PKT_RESPONSE_STAGE_REJECTED, HFB_ERR_SESSION_BUSY, NULL, 0);
        return;
    }
    respond(c, sequence, opcode, HFB_PKT_RESPONSE_STAGE_ACCEPTED, HFB_ERR_OK, NULL, 0);

    /* 3: a fresh session.  The new owner is installed first, because events go to the
       telemetry destination current when they are sent, which SPEC 7 says is the new
       owner's; then an open session goes to the safe state (disarm, stop the profile,
       IDLE). */
    do {
        dev.token = random_token();
    } while (dev.token == 0u);
    dev.owner = c;
    dev.owner_since_tick = dev.tick;
    dev.telemetry_port = a.telemetry_port;
    dev.watchdog_reset_tick = dev.tick;          /* SPEC 9.1: CONNECT starts the count */
    dev.watchdog_state = HFB_PKT_HOUSEKEEPING_WATCHDOG_OK;
    if (was_open) {
        /* SPEC 7: SESSION_TAKEN_OVER first, then the safe state's own events */
        event_send(HFB_PKT_EVENT_LEVEL_WARNING, HFB_EVT_SESSION_TAKEN_OVER,
                   "session taken over: safe state (disarmed, profile stopped, IDLE)");
        control_safe_state();
    }

    reply.session_token = dev.token;
    reply.tick = dev.tick;
    (void)hfb_cmd_connect_reply_pack(&reply, data, sizeof data);
    respond(c, sequence, opcode, HFB_PKT_RESPONSE_STAGE_COMPLETED, HFB_ERR_OK, data, sizeof data);
    event_send(HFB_PKT_EVENT_LEVEL_INFO, HFB_EVT_SESSION_OPENED, "session opened");
}

/* SPEC 7 "Ending a session": DISCONNECT or the owner's connection closed. */
void session_end(const char *why)
{
    if (dev.token == 0u) {
        return;
    }
    if (dev.armed) {
        control_disarm("session ended", 1);     /* motors zero, profile stopped */
        control_set_mode(HFB_PKT_HIGH_RATE_MODE_IDLE);
    }
    event_send(HFB_PKT_EVENT_LEVEL_INFO, HFB_EVT_SESSION_CLOSED, why);
    dev.token = 0u;                             /* stops telemetry too */
    dev.owner = -1;
    dev.watchdog_state = HFB_PKT_HOUSEKEEPING_WATCHDOG_NO_SESSION;
}

void session_connection_closed(int c)
{
    if (dev.token != 0u && c == dev.owner) {
        session_end("session closed: the owner's connection closed");
    }
}
