/*
 * commands.c - SPEC 6: the command exchange.
 *
 * Every intact COMMAND frame (the kit's deframer, SPEC 4.1, found it on one connection)
 * comes here.  In order:
 *   - the retry history (SPEC 6.4), before any check: a known (connection, sequence, opcode)
 *     gets its recorded RESPONSE payloads again, in new frames, and nothing else;
 *   - the checks of SPEC 6.3 in their order: opcode, length, session token, argument
 *     ranges (the dictionary's), then each command's own rules (state, staging, its own
 *     bounds); the first failure is the REJECTED reason;
 *   - ACCEPTED, execution, COMPLETED or FAILED.
 * Every command finishes within the same pass of the loop, between two control periods,
 * so no command is ever "still executing" when its retry arrives.
 */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "device.h"

static history_entry_t *recording;   /* the history entry of the command being answered */

/* ---- sending RESPONSE frames; each one is also recorded for retries -------------- */
void respond(int c, uint32_t sequence, uint16_t opcode, uint8_t stage, uint16_t reason,
             const uint8_t *data, size_t n)
{
    hfb_pkt_response_t r;
    uint8_t payload[HFB_MAX_PAYLOAD];
    uint8_t frame[HFB_MAX_FRAME];
    size_t len, flen;
    r.command_sequence = sequence;
    r.opcode = opcode;
    r.stage = stage;
    r.reason = reason;
    r.data = data;
    r.data_len = n;
    len = hfb_pkt_response_pack(&r, payload, sizeof payload);
    if (recording != NULL && recording->n < 2) {
        memcpy(recording->payload[recording->n], payload, len);
        recording->len[recording->n] = len;
        recording->n++;
    }
    if (stage == HFB_PKT_RESPONSE_STAGE_ACCEPTED) {
        dev.commands_accepted++;              /* SPEC 5.2: new commands only, not replays */
    } else if (stage == HFB_PKT_RESPONSE_STAGE_REJECTED) {
        dev.commands_rejected++;
    }
    flen = frame_build(frame, HFB_PKT_RESPONSE_ID, dev.seq_response, payload, len);
    if (flen > 0u && net_send_tcp(c, frame, flen) == 0) {
        dev.seq_response++;
    }
}

static void reject(int c, uint32_t seq, uint16_t op, uint16_t reason)
{
    respond(c, seq, op, HFB_PKT_RESPONSE_STAGE_REJECTED, reason, NULL, 0);
}

static void accept_and_complete(int c, uint32_t seq, uint16_t op, const uint8_t *reply, size_t n)
{
    respond(c, seq, op, HFB_PKT_RESPONSE_STAGE_ACCEPTED, HFB_ERR_OK, NULL, 0);
    respond(c, seq, op, HFB_PKT_RESPONSE_STAGE_COMPLETED, HFB_ERR_OK, reply, n);
}

/* ---- retries (SPEC 6.4) -------------------------------------------------------------- */
/* Keyed by connection too: a retry always comes on the connection of the original, and a
   history shared by all connections would hand another host the owner's recorded CONNECT
   reply - the session token - for the price of guessing a sequence number. */
static uint32_t history_key(int c)
{
    return (dev.deviations & DEV_SHARED_HISTORY) ? 0u : dev.conn[c].serial;
}

static history_entry_t *history_find(uint32_t conn, uint32_t seq, uint16_t op)
{
    int i;
    for (i = 0; i < HISTORY_SIZE; i++) {
        history_entry_t *h = &dev.history[i];
        if (h->used && h->connection == conn && h->sequence == seq && h->opcode == op) {
            return h;
        }
    }
    return NULL;
}

static history_entry_t *history_new(uint32_t conn, uint32_t seq, uint16_t op)
{
    history_entry_t *h = &dev.history[dev.history_next];   /* the oldest is forgotten */
    dev.history_next = (dev.history_next + 1) % HISTORY_SIZE;
    h->used = 1;
    h->connection = conn;
    h->sequence = seq;
    h->opcode = op;
    h->n = 0;
    return h;
}

static void replay(int c, const history_entry_t *h)
{
    int i;
    for (i = 0; i < h->n; i++) {
        uint8_t frame[HFB_MAX_FRAME];
        size_t flen = frame_build(frame, HFB_PKT_RESPONSE_ID, dev.seq_response, h->payload[i], h->len[i]);
        if (flen > 0u && net_send_tcp(c, frame, flen) == 0) {
            dev.seq_response++;               /* new frames: the RESPONSE counter advances */
        }
    }
}

/* ---- the commands, after checks 1-3 ------------------------------------------------- */
static void cmd_set_mode(int c, uint32_t seq, uint16_t op, const uint8_t *a)
{
    uint8_t m = hfb_get_u8(a + HFB_CMD_SET_MODE_ARGS_MODE_OFFSET);
    if (m != HFB_CMD_SET_MODE_ARGS_MODE_IDLE && dev.armed) {
        reject(c, seq, op, HFB_ERR_INVALID_STATE);           /* SPEC 10: only while disarmed */
        return;
    }
    respond(c, seq, op, HFB_PKT_RESPONSE_STAGE_ACCEPTED, HFB_ERR_OK, NULL, 0);
    if (m == HFB_CMD_SET_MODE_ARGS_MODE_IDLE && dev.armed) {
        control_disarm("SET_MODE IDLE", 1);
    }
    control_set_mode(m);
    respond(c, seq, op, HFB_PKT_RESPONSE_STAGE_COMPLETED, HFB_ERR_OK, NULL, 0);
}

static void cmd_arm(int c, uint32_t seq, uint16_t op)
{
    if (dev.fault_code != HFB_PKT_HOUSEKEEPING_FAULT_CODE_NONE) {
        reject(c, seq, op, HFB_ERR_FAULT_LATCHED);
        return;
    }
    if (dev.mode == HFB_PKT_HIGH_RATE_MODE_IDLE) {
        reject(c, seq, op, HFB_ERR_INVALID_STATE);
        return;
    }
    respond(c, seq, op, HFB_PKT_RESPONSE_STAGE_ACCEPTED, HFB_ERR_OK, NULL, 0);
    if (!dev.armed) {
        control_arm();                                       /* already armed: nothing changes */
    }
    respond(c, seq, op, HFB_PKT_RESPONSE_STAGE_COMPLETED, HFB_ERR_OK, NULL, 0);
}

static void cmd_disarm(int c, uint32_t seq, uint16_t op)
{
    respond(c, seq, op, HFB_PKT_RESPONSE_STAGE_ACCEPTED, HFB_ERR_OK, NULL, 0);
    if (dev.armed) {
        control_disarm("DISARM", 1);
    }
    /* SPEC 9.2: DISARM acknowledges a latched fault */
    dev.fault_code = HFB_PKT_HOUSEKEEPING_FAULT_CODE_NONE;
    if (dev.watchdog_state == HFB_PKT_HOUSEKEEPING_WATCHDOG_EXPIRED) {
        dev.watchdog_state = HFB_PKT_HOUSEKEEPING_WATCHDOG_OK;
    }
    respond(c, seq, op, HFB_PKT_RESPONSE_STAGE_COMPLETED, HFB_ERR_OK, NULL, 0);
}

static void cmd_abort(int c, uint32_t seq, uint16_t op)
{
    /* SPEC 9.2: anyone, always; no fault is latched, the session stays */
    respond(c, seq, op, HFB_PKT_RESPONSE_STAGE_ACCEPTED, HFB_ERR_OK, NULL, 0);
    if (dev.armed) {
        control_disarm("ABORT", 1);
    }
    profile_stop(0);
    control_set_mode(HFB_PKT_HIGH_RATE_MODE_IDLE);
    event_send(HFB_PKT_EVENT_LEVEL_WARNING, HFB_EVT_ABORTED, "ABORT: motors zero, disarmed, IDLE");
    respond(c, seq, op, HFB_PKT_RESPONSE_STAGE_COMPLETED, HFB_ERR_OK, NULL, 0);
}

static void cmd_friction_comp(int c, uint32_t seq, uint16_t op, const uint8_t *a)
{
    uint8_t e = hfb_get_u8(a + HFB_CMD_FRICTION_COMP_ARGS_ENABLE_OFFSET);
    dev.friction_comp_on = e;
    accept_and_complete(c, seq, op, NULL, 0);
}

static void cmd_set_currents(int c, uint32_t seq, uint16_t op, const uint8_t *a)
{
    float i1 = hfb_get_f32(a + HFB_CMD_SET_CURRENTS_ARGS_CURRENT_COARSE_OFFSET);
    float i2 = hfb_get_f32(a + HFB_CMD_SET_CURRENTS_ARGS_CURRENT_FINE_OFFSET);
    if (dev.mode != HFB_PKT_HIGH_RATE_MODE_OPEN_LOOP) {
        reject(c, seq, op, HFB_ERR_INVALID_STATE);
        return;
    }
    if (!dev.armed) {
        reject(c, seq, op, HFB_ERR_NOT_ARMED);
        return;
    }
    dev.current_cmd_coarse = i1;
    dev.current_cmd_fine = i2;
    accept_and_complete(c, seq, op, NULL, 0);
}

static void cmd_set_reference(int c, uint32_t seq, uint16_t op, const uint8_t *a)
{
    float r = hfb_get_f32(a + HFB_CMD_SET_REFERENCE_ARGS_REFERENCE_OFFSET);
    if (dev.mode != HFB_PKT_HIGH_RATE_MODE_RELATIVE && dev.mode != HFB_PKT_HIGH_RATE_MODE_INERTIAL) {
        reject(c, seq, op, HFB_ERR_INVALID_STATE);
        return;
    }
    dev.reference = r;
    accept_and_complete(c, seq, op, NULL, 0);
}

/* ---- parameter table (SPEC 11.1) ------------------------------------------------- */
static void cmd_param_begin(int c, uint32_t seq, uint16_t op, const uint8_t *a)
{
    uint16_t version = hfb_get_u16(a + HFB_CMD_PARAM_BEGIN_ARGS_TABLE_VERSION_OFFSET);
    uint32_t length = hfb_get_u32(a + HFB_CMD_PARAM_BEGIN_ARGS_TABLE_LENGTH_OFFSET);
    if (length != HFB_PARAM_TABLE_SIZE) {         /* SPEC 11.1: the device's own table size */
        reject(c, seq, op, HFB_ERR_OUT_OF_RANGE);
        return;
    }
    respond(c, seq, op, HFB_PKT_RESPONSE_STAGE_ACCEPTED, HFB_ERR_OK, NULL, 0);
    free(dev.param_staging);                 /* discards any earlier staging */
    dev.param_staging = calloc(length, 1);   /* zero-filled */
    if (dev.param_staging == NULL) {
        respond(c, seq, op, HFB_PKT_RESPONSE_STAGE_FAILED, HFB_ERR_INTERNAL_ERROR, NULL, 0);
        return;
    }
    dev.param_staging_length = length;
    dev.param_staging_version = version;
    respond(c, seq, op, HFB_PKT_RESPONSE_STAGE_COMPLETED, HFB_ERR_OK, NULL, 0);
}

static void cmd_param_write(int c, uint32_t seq, uint16_t op, const uint8_t *a, size_t n)
{
    uint32_t offset = hfb_get_u32(a + HFB_CMD_PARAM_WRITE_ARGS_OFFSET_OFFSET);
    size_t len = n - HFB_CMD_PARAM_WRITE_ARGS_SIZE;
    /* SPEC 6.3: the offset is judged against the staging, after NOTHING_STAGED */
    if (dev.param_staging == NULL) {
        reject(c, seq, op, HFB_ERR_NOTHING_STAGED);
        return;
    }
    if ((uint64_t)offset + len > dev.param_staging_length) {
        reject(c, seq, op, HFB_ERR_OUT_OF_RANGE);
        return;
    }
    memcpy(dev.param_staging + offset, a + HFB_CMD_PARAM_WRITE_ARGS_DATA_OFFSET, len);
    accept_and_complete(c, seq, op, NULL, 0);
}

static void cmd_param_commit(int c, uint32_t seq, uint16_t op, const uint8_t *a)
{
    uint32_t crc = hfb_get_u32(a + HFB_CMD_PARAM_COMMIT_ARGS_TABLE_CRC_OFFSET);
    char why[200];
    hfb_cmd_param_commit_reply_t reply;
    uint8_t data[HFB_CMD_PARAM_COMMIT_REPLY_SIZE];
    if (dev.param_staging == NULL) {
        reject(c, seq, op, HFB_ERR_NOTHING_STAGED);
        return;
    }
    if (dev.armed) {
        reject(c, seq, op, HFB_ERR_INVALID_STATE);
        return;
    }
    respond(c, seq, op, HFB_PKT_RESPONSE_STAGE_ACCEPTED, HFB_ERR_OK, NULL, 0);
    if (!(dev.deviations & DEV_COMMIT_NO_CRC)
        && hfb_crc32(dev.param_staging, dev.param_staging_length) != crc) {
        respond(c, seq, op, HFB_PKT_RESPONSE_STAGE_FAILED, HFB_ERR_CRC_MISMATCH, NULL, 0);
        return;                              /* the staging is kept for another try */
    }
    if (params_validate(dev.param_staging, why, sizeof why) != 0) {
        respond(c, seq, op, HFB_PKT_RESPONSE_STAGE_FAILED, HFB_ERR_VALIDATION_FAILED, NULL, 0);
        return;
    }
    /* Commands run between two control periods: period dev.tick ran entirely with the
       old table, period dev.tick + 1 will run entirely with the new one - the cycle
       boundary SPEC 11.1 asks for, and the tick the reply names. */
    params_activate(dev.param_staging, dev.param_staging_version);
    free(dev.param_staging);                 /* consumed */
    dev.param_staging = NULL;
    reply.table_crc = dev.table_crc;
    reply.tick = dev.tick;
    (void)hfb_cmd_param_commit_reply_pack(&reply, data, sizeof data);
    respond(c, seq, op, HFB_PKT_RESPONSE_STAGE_COMPLETED, HFB_ERR_OK, data, sizeof data);
    {
        char text[80];
        (void)snprintf(text, sizeof text, "parameter table version %u active (crc 0x%08lX)",
                       (unsigned)dev.table_version, (unsigned long)dev.table_crc);
        event_send(HFB_PKT_EVENT_LEVEL_INFO, HFB_EVT_PARAMETERS_ACTIVATED, text);
    }
}

static void cmd_param_read(int c, uint32_t seq, uint16_t op, const uint8_t *a)
{
    uint32_t offset = hfb_get_u32(a + HFB_CMD_PARAM_READ_ARGS_OFFSET_OFFSET);
    uint16_t count = hfb_get_u16(a + HFB_CMD_PARAM_READ_ARGS_COUNT_OFFSET);
    hfb_cmd_param_read_reply_t reply;
    uint8_t data[HFB_CMD_PARAM_READ_REPLY_SIZE + HFB_CMD_PARAM_READ_ARGS_COUNT_MAX];
    size_t n;
    if ((uint64_t)offset + count > HFB_PARAM_TABLE_SIZE) {       /* within the table */
        reject(c, seq, op, HFB_ERR_OUT_OF_RANGE);
        return;
    }
    reply.offset = offset;
    reply.data = dev.table + offset;
    reply.data_len = count;
    n = hfb_cmd_param_read_reply_pack(&reply, data, sizeof data);
    accept_and_complete(c, seq, op, data, n);
}

/* ---- profiles (SPEC 11.2) ----------------------------------------------------------- */
static void cmd_profile_begin(int c, uint32_t seq, uint16_t op, const uint8_t *a)
{
    uint16_t id = hfb_get_u16(a + HFB_CMD_PROFILE_BEGIN_ARGS_PROFILE_ID_OFFSET);
    uint8_t target = hfb_get_u8(a + HFB_CMD_PROFILE_BEGIN_ARGS_TARGET_OFFSET);
    uint32_t count = hfb_get_u32(a + HFB_CMD_PROFILE_BEGIN_ARGS_SAMPLE_COUNT_OFFSET);
    if (dev.profile_playing) {
        reject(c, seq, op, HFB_ERR_INVALID_STATE);
        return;
    }
    respond(c, seq, op, HFB_PKT_RESPONSE_STAGE_ACCEPTED, HFB_ERR_OK, NULL, 0);
    free(dev.profile_staging);
    dev.profile_staging = calloc(count, 4u);
    if (dev.profile_staging == NULL) {
        respond(c, seq, op, HFB_PKT_RESPONSE_STAGE_FAILED, HFB_ERR_INTERNAL_ERROR, NULL, 0);
        return;
    }
    dev.profile_staging_count = count;
    dev.profile_staging_id = id;
    dev.profile_staging_target = target;
    respond(c, seq, op, HFB_PKT_RESPONSE_STAGE_COMPLETED, HFB_ERR_OK, NULL, 0);
}

static void cmd_profile_write(int c, uint32_t seq, uint16_t op, const uint8_t *a, size_t n)
{
    uint32_t offset = hfb_get_u32(a + HFB_CMD_PROFILE_WRITE_ARGS_OFFSET_OFFSET);
    size_t samples = (n - HFB_CMD_PROFILE_WRITE_ARGS_SIZE) / 4u;
    if (dev.profile_staging == NULL) {
        reject(c, seq, op, HFB_ERR_NOTHING_STAGED);
        return;
    }
    if ((uint64_t)offset + samples > dev.profile_staging_count) {
        reject(c, seq, op, HFB_ERR_OUT_OF_RANGE);
        return;
    }
    memcpy(dev.profile_staging + (size_t)offset * 4u, a + HFB_CMD_PROFILE_WRITE_ARGS_SAMPLES_OFFSET,
           samples * 4u);
    accept_and_complete(c, seq, op, NULL, 0);
}

static void cmd_profile_commit(int c, uint32_t seq, uint16_t op, const uint8_t *a)
{
    uint32_t crc = hfb_get_u32(a + HFB_CMD_PROFILE_COMMIT_ARGS_PROFILE_CRC_OFFSET);
    uint32_t i;
    if (dev.profile_staging == NULL) {
        reject(c, seq, op, HFB_ERR_NOTHING_STAGED);
        return;
    }
    /* SPEC 11.2: never swap the samples under playback (possible only with a staging
       opened before the start, since PROFILE_BEGIN is refused while playing) */
    if (dev.profile_playing) {
        reject(c, seq, op, HFB_ERR_INVALID_STATE);
        return;
    }
    respond(c, seq, op, HFB_PKT_RESPONSE_STAGE_ACCEPTED, HFB_ERR_OK, NULL, 0);
    if (hfb_crc32(dev.profile_staging, (size_t)dev.profile_staging_count * 4u) != crc) {
        respond(c, seq, op, HFB_PKT_RESPONSE_STAGE_FAILED, HFB_ERR_CRC_MISMATCH, NULL, 0);
        return;
    }
    for (i = 0; i < dev.profile_staging_count; i++) {
        if (!profile_sample_valid(dev.profile_staging_target, hfb_get_f32(dev.profile_staging + 4u * i))) {
            respond(c, seq, op, HFB_PKT_RESPONSE_STAGE_FAILED, HFB_ERR_VALIDATION_FAILED, NULL, 0);
            return;
        }
    }
    free(dev.profile);
    dev.profile = dev.profile_staging;       /* the staging is consumed */
    dev.profile_count = dev.profile_staging_count;
    dev.profile_id = dev.profile_staging_id;
    dev.profile_target = dev.profile_staging_target;
    dev.profile_staging = NULL;
    respond(c, seq, op, HFB_PKT_RESPONSE_STAGE_COMPLETED, HFB_ERR_OK, NULL, 0);
}

static void cmd_profile_start(int c, uint32_t seq, uint16_t op)
{
    if (dev.profile == NULL) {
        reject(c, seq, op, HFB_ERR_NOTHING_STAGED);
        return;
    }
    if (!dev.armed) {
        reject(c, seq, op, HFB_ERR_NOT_ARMED);
        return;
    }
    if (!profile_target_plays_in_mode(dev.profile_target, dev.mode)) {
        reject(c, seq, op, HFB_ERR_INVALID_STATE);
        return;
    }
    respond(c, seq, op, HFB_PKT_RESPONSE_STAGE_ACCEPTED, HFB_ERR_OK, NULL, 0);
    profile_start();
    respond(c, seq, op, HFB_PKT_RESPONSE_STAGE_COMPLETED, HFB_ERR_OK, NULL, 0);
}

static void cmd_profile_stop(int c, uint32_t seq, uint16_t op)
{
    respond(c, seq, op, HFB_PKT_RESPONSE_STAGE_ACCEPTED, HFB_ERR_OK, NULL, 0);
    if (dev.profile_playing) {
        profile_stop(1);
    }
    respond(c, seq, op, HFB_PKT_RESPONSE_STAGE_COMPLETED, HFB_ERR_OK, NULL, 0);
}

static void cmd_get_info(int c, uint32_t seq, uint16_t op)
{
    static const char description[] =
        "C reference device (firmware/reference_device): stand-in plant, two damped "
        "double-integrator axes coupled by a flexure, no real hardware";
    hfb_cmd_get_info_reply_t r;
    uint8_t data[HFB_CMD_GET_INFO_REPLY_SIZE + sizeof description];
    size_t n;
    r.firmware_version = FIRMWARE_VERSION;
    r.protocol_major = HFB_PROTOCOL_VERSION_MAJOR;
    r.protocol_minor = HFB_PROTOCOL_VERSION_MINOR;
    r.dictionary_hash = HFB_DICTIONARY_HASH;
    r.tick = dev.tick;
    r.description = (const uint8_t *)description;
    r.description_len = sizeof description - 1u;
    n = hfb_cmd_get_info_reply_pack(&r, data, sizeof data);
    accept_and_complete(c, seq, op, data, n);
}

static void cmd_heartbeat(int c, uint32_t seq, uint16_t op)
{
    hfb_cmd_heartbeat_reply_t r;
    uint8_t data[HFB_CMD_HEARTBEAT_REPLY_SIZE];
    r.tick = dev.tick;
    (void)hfb_cmd_heartbeat_reply_pack(&r, data, sizeof data);
    accept_and_complete(c, seq, op, data, sizeof data);
}

static void cmd_disconnect(int c, uint32_t seq, uint16_t op)
{
    respond(c, seq, op, HFB_PKT_RESPONSE_STAGE_ACCEPTED, HFB_ERR_OK, NULL, 0);
    session_end("session closed: DISCONNECT");
    /* SPEC 7: COMPLETED still goes out on the command connection */
    respond(c, seq, op, HFB_PKT_RESPONSE_STAGE_COMPLETED, HFB_ERR_OK, NULL, 0);
}

static void not_owner(int c, uint32_t seq, uint16_t op, const char *name)
{
    char text[160];
    session_owner_text(text, sizeof text);
    respond(c, seq, op, HFB_PKT_RESPONSE_STAGE_REJECTED, HFB_ERR_NOT_SESSION_OWNER,
            (const uint8_t *)text, strlen(text));
    if (dev.token != 0u) {
        char ev[120];
        (void)snprintf(ev, sizeof ev, "%s rejected: wrong or missing session token", name);
        event_send(HFB_PKT_EVENT_LEVEL_WARNING, HFB_EVT_COMMAND_REJECTED, ev);
    }
}

static void dispatch(int c, uint32_t seq, const hfb_pkt_command_t *cmd)
{
    const hfb_command_info_t *info = hfb_command_info(cmd->opcode);
    const uint8_t *a = cmd->arguments;
    size_t n = cmd->arguments_len;
    uint16_t op = cmd->opcode;
    uint8_t k;

    /* SPEC 6.3 check 1 */
    if (info == NULL) {
        reject(c, seq, op, HFB_ERR_UNKNOWN_COMMAND);
        return;
    }
    /* check 2, with PROFILE_WRITE's multiple of 4 */
    if (n < info->args_size || (!info->args_variable && n != info->args_size)
        || (op == HFB_CMD_PROFILE_WRITE_OPCODE && (n - info->args_size) % 4u != 0u)) {
        reject(c, seq, op, HFB_ERR_BAD_LENGTH);
        return;
    }
    /* check 3 */
    if (info->needs_session && (dev.token == 0u || cmd->session_token != dev.token)) {
        not_owner(c, seq, op, info->name);
        return;
    }
    /* check 4 as commands.toml states it: every argument's range and states, floats
       finite (f32 compared in f32, SPEC 3.2), from the kit's table of the command's
       arguments - a range changed in the TOML needs a new export, no edit here */
    for (k = 0; k < info->arg_count; k++) {
        if (!hfb_arg_valid(&info->args[k], a)) {
            reject(c, seq, op, HFB_ERR_OUT_OF_RANGE);
            return;
        }
    }
    /* SPEC 9.1: a command with needs_session that passed checks 1-4 resets the watchdog,
       whatever check 5 then says */
    if (info->needs_session) {
        dev.watchdog_reset_tick = dev.tick;
    }
    /* check 5 (the command's own bounds - staged sizes, the table size - and the state
       rules of SPEC 10 and 11, in each command's order) and execution, per command */
    switch (op) {
    case HFB_CMD_CONNECT_OPCODE: session_connect(c, seq, op, a, n); return;
    case HFB_CMD_DISCONNECT_OPCODE: cmd_disconnect(c, seq, op); return;
    case HFB_CMD_HEARTBEAT_OPCODE: cmd_heartbeat(c, seq, op); return;
    case HFB_CMD_GET_INFO_OPCODE: cmd_get_info(c, seq, op); return;
    case HFB_CMD_SET_MODE_OPCODE: cmd_set_mode(c, seq, op, a); return;
    case HFB_CMD_ARM_OPCODE: cmd_arm(c, seq, op); return;
    case HFB_CMD_DISARM_OPCODE: cmd_disarm(c, seq, op); return;
    case HFB_CMD_ABORT_OPCODE: cmd_abort(c, seq, op); return;
    case HFB_CMD_FRICTION_COMP_OPCODE: cmd_friction_comp(c, seq, op, a); return;
    case HFB_CMD_SET_CURRENTS_OPCODE: cmd_set_currents(c, seq, op, a); return;
    case HFB_CMD_SET_REFERENCE_OPCODE: cmd_set_reference(c, seq, op, a); return;
    case HFB_CMD_PARAM_BEGIN_OPCODE: cmd_param_begin(c, seq, op, a); return;
    case HFB_CMD_PARAM_WRITE_OPCODE: cmd_param_write(c, seq, op, a, n); return;
    case HFB_CMD_PARAM_COMMIT_OPCODE: cmd_param_commit(c, seq, op, a); return;
    case HFB_CMD_PARAM_READ_OPCODE: cmd_param_read(c, seq, op, a); return;
    case HFB_CMD_PROFILE_BEGIN_OPCODE: cmd_profile_begin(c, seq, op, a); return;
    case HFB_CMD_PROFILE_WRITE_OPCODE: cmd_profile_write(c, seq, op, a, n); return;
    case HFB_CMD_PROFILE_COMMIT_OPCODE: cmd_profile_commit(c, seq, op, a); return;
    case HFB_CMD_PROFILE_START_OPCODE: cmd_profile_start(c, seq, op); return;
    case HFB_CMD_PROFILE_STOP_OPCODE: cmd_profile_stop(c, seq, op); return;
    default:
        /* in the dictionary but not known to this firmware: the kit and this file
           disagree, which the kit drift test should have caught */
        respond(c, seq, op, HFB_PKT_RESPONSE_STAGE_ACCEPTED, HFB_ERR_OK, NULL, 0);
        respond(c, seq, op, HFB_PKT_RESPONSE_STAGE_FAILED, HFB_ERR_INTERNAL_ERROR, NULL, 0);
        return;
    }
}

/* the deframer's handler: one good frame of one connection */
void commands_on_frame(void *context, const uint8_t *frame, size_t length)
{
    int c = (int)((connection_t *)context - dev.conn);
    hfb_frame_view_t view;
    hfb_pkt_command_t cmd;
    history_entry_t *h;
    if (hfb_frame_view(frame, length, &view) != 0 || view.packet_id != HFB_PKT_COMMAND_ID
        || hfb_pkt_command_unpack(&cmd, view.payload, view.length) != 0) {
        return;                              /* a host sends only COMMAND; the rest is ignored */
    }
    /* SPEC 6.4: the history is looked up before any check */
    h = history_find(history_key(c), view.sequence, cmd.opcode);
    if (h != NULL && !(dev.deviations & DEV_RETRY_TWICE)) {
        replay(c, h);
        return;
    }
    recording = history_new(history_key(c), view.sequence, cmd.opcode);
    dispatch(c, view.sequence, &cmd);
    recording = NULL;
}

/* The deframer's handler for a frame of another major version (intact, but dropped by
   framing as a version error): SPEC 7 asks a CONNECT in it to be answered REJECTED
   DICTIONARY_MISMATCH, in a frame of this device's version, so the host can tell which
   side to update.  The header, COMMAND payload and CONNECT layout are the same in every
   major version (SPEC 7); anything else of another version gets no answer. */
void commands_on_other_version(void *context, const uint8_t *frame, size_t length)
{
    int c = (int)((connection_t *)context - dev.conn);
    hfb_frame_view_t view;
    hfb_pkt_command_t cmd;
    if (hfb_frame_view(frame, length, &view) != 0 || view.packet_id != HFB_PKT_COMMAND_ID
        || hfb_pkt_command_unpack(&cmd, view.payload, view.length) != 0
        || cmd.opcode != HFB_CMD_CONNECT_OPCODE) {
        return;
    }
    session_refuse_dictionary(c, view.sequence, cmd.opcode);
}
