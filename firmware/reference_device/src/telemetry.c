/*
 * telemetry.c - the device's frames: encoding (SPEC 2), HIGH_RATE (5.1), HOUSEKEEPING
 * (5.2) and EVENT (5.3).
 *
 * Sequence numbers: one counter per packet id (SPEC 2).  A frame that could not be sent
 * does not use up a number, so a counter only advances after the transport took the
 * frame; the host then reads a sequence gap as loss in transit only.
 */
#include <math.h>
#include <string.h>

#include "device.h"

/* The kit's encoder, plus the one deliberate deviation that lives at this level:
   --deviate crc-range recomputes the CRC over one byte too few. */
size_t frame_build(uint8_t *frame, uint8_t packet_id, uint32_t sequence, const uint8_t *payload,
                   size_t payload_len)
{
    size_t n = hfb_frame_encode(frame, HFB_MAX_FRAME, packet_id, sequence, dev.tick, payload,
                                payload_len);
    if (n > 0u && (dev.deviations & DEV_CRC_RANGE)) {
        uint32_t crc = hfb_crc32(frame, HFB_HEADER_SIZE + payload_len - 1u);
        uint8_t *p = frame + HFB_HEADER_SIZE + payload_len;
        p[0] = (uint8_t)crc;
        p[1] = (uint8_t)(crc >> 8);
        p[2] = (uint8_t)(crc >> 16);
        p[3] = (uint8_t)(crc >> 24);
    }
    return n;
}

/* send one telemetry frame; the counter advances only if it went out */
static int send_telemetry(uint8_t packet_id, uint32_t *counter, const uint8_t *payload, size_t n)
{
    uint8_t frame[HFB_MAX_FRAME];
    size_t len = frame_build(frame, packet_id, *counter, payload, n);
    if (len == 0u || net_send_telemetry(frame, len) != 0) {
        return -1;
    }
    (*counter)++;
    return 0;
}

void telemetry_high_rate(const period_record_t *r)
{
    hfb_pkt_high_rate_t hr;
    uint8_t payload[HFB_PKT_HIGH_RATE_SIZE];
    if (dev.token == 0u) {
        return;                                   /* SPEC 1.3 */
    }
    memset(&hr, 0, sizeof hr);
    hr.mode = dev.mode;
    hr.status = (uint8_t)((dev.armed ? HFB_PKT_HIGH_RATE_STATUS_ARMED_MASK : 0u)
                          | (r->coarse_saturated ? HFB_PKT_HIGH_RATE_STATUS_COARSE_SATURATED_MASK : 0u)
                          | (r->fine_saturated ? HFB_PKT_HIGH_RATE_STATUS_FINE_SATURATED_MASK : 0u)
                          | (dev.profile_index_shown ? HFB_PKT_HIGH_RATE_STATUS_PROFILE_ACTIVE_MASK : 0u)
                          | (dev.friction_comp_on ? HFB_PKT_HIGH_RATE_STATUS_FRICTION_COMP_ON_MASK : 0u)
                          | (dev.fault_code ? HFB_PKT_HIGH_RATE_STATUS_FAULT_MASK : 0u));
    hr.encoder_outer = hfb_counts_i32(r->phi1, HFB_PKT_HIGH_RATE_ENCODER_OUTER_SCALE, 0.0);
    hr.encoder_inner = hfb_counts_i32(r->phi2, HFB_PKT_HIGH_RATE_ENCODER_INNER_SCALE, 0.0);
    hr.encoder_base = hfb_counts_i32(r->base, HFB_PKT_HIGH_RATE_ENCODER_BASE_SCALE, 0.0);
    hr.gyro_rate = hfb_counts_i32(r->gyro, HFB_PKT_HIGH_RATE_GYRO_RATE_SCALE, 0.0);
    hr.autocollimator = hfb_counts_i16(r->autocollimator, HFB_PKT_HIGH_RATE_AUTOCOLLIMATOR_SCALE, 0.0);
    hr.los_estimate = hfb_counts_i32(dev.los_estimate, HFB_PKT_HIGH_RATE_LOS_ESTIMATE_SCALE, 0.0);
    hr.reference = hfb_counts_i32(dev.reference, HFB_PKT_HIGH_RATE_REFERENCE_SCALE, 0.0);
    hr.error_angle = (float)r->error_angle;
    hr.error_rate = (float)r->error_rate;
    hr.torque_coarse_cmd = (float)r->u1;
    hr.torque_fine_cmd = (float)r->u2;
    hr.current_coarse = hfb_counts_i16(r->current_coarse, HFB_PKT_HIGH_RATE_CURRENT_COARSE_SCALE, 0.0);
    hr.current_fine = hfb_counts_i16(r->current_fine, HFB_PKT_HIGH_RATE_CURRENT_FINE_SCALE, 0.0);
    hr.voltage_coarse = hfb_counts_i16(r->voltage_coarse, HFB_PKT_HIGH_RATE_VOLTAGE_COARSE_SCALE, 0.0);
    hr.voltage_fine = hfb_counts_i16(r->voltage_fine, HFB_PKT_HIGH_RATE_VOLTAGE_FINE_SCALE, 0.0);
    hr.friction_comp_torque = (float)r->t_fc;
    hr.profile_index = dev.profile_index_shown;
    (void)hfb_pkt_high_rate_pack(&hr, payload, sizeof payload);
    if (send_telemetry(HFB_PKT_HIGH_RATE_ID, &dev.seq_high_rate, payload, sizeof payload) != 0) {
        dev.telemetry_overruns++;                 /* SPEC 5.1: a period not sent */
    }
}

void telemetry_housekeeping(void)
{
    hfb_pkt_housekeeping_t hk;
    uint8_t payload[HFB_PKT_HOUSEKEEPING_SIZE];
    double t_coarse, t_fine, t_flex, t_elec;
    uint32_t age_ticks = dev.tick - dev.watchdog_reset_tick;
    double age_ms = (double)age_ticks * 1000.0 / (double)HFB_CONTROL_RATE_HZ;
    if (dev.token == 0u) {
        return;
    }
    plant_temperatures(&t_coarse, &t_fine, &t_flex, &t_elec);
    memset(&hk, 0, sizeof hk);
    hk.temp_motor_coarse = hfb_counts_i16(t_coarse, HFB_PKT_HOUSEKEEPING_TEMP_MOTOR_COARSE_SCALE, 0.0);
    hk.temp_motor_fine = hfb_counts_i16(t_fine, HFB_PKT_HOUSEKEEPING_TEMP_MOTOR_FINE_SCALE, 0.0);
    hk.temp_flexure = hfb_counts_i16(t_flex, HFB_PKT_HOUSEKEEPING_TEMP_FLEXURE_SCALE, 0.0);
    hk.temp_electronics = hfb_counts_i16(t_elec, HFB_PKT_HOUSEKEEPING_TEMP_ELECTRONICS_SCALE, 0.0);
    hk.supply_motor = hfb_counts_u16(28.0, HFB_PKT_HOUSEKEEPING_SUPPLY_MOTOR_SCALE, 0.0);
    hk.supply_logic = hfb_counts_u16(5.0, HFB_PKT_HOUSEKEEPING_SUPPLY_LOGIC_SCALE, 0.0);
    hk.firmware_version = FIRMWARE_VERSION;
    hk.uptime = dev.tick / HFB_CONTROL_RATE_HZ;
    hk.param_table_crc = dev.table_crc;
    hk.param_table_version = dev.table_version;
    hk.active_profile = dev.profile != NULL ? dev.profile_id : 0u;
    hk.watchdog = dev.watchdog_state;
    /* SPEC 9.1: milliseconds since the last reset, saturating at 65535 */
    hk.heartbeat_age = (uint16_t)(age_ms >= 65535.0 ? 65535.0 : floor(age_ms));
    hk.commands_accepted = dev.commands_accepted;
    hk.commands_rejected = dev.commands_rejected;
    hk.fault_code = dev.fault_code;
    hk.telemetry_overruns = dev.telemetry_overruns;
    (void)hfb_pkt_housekeeping_pack(&hk, payload, sizeof payload);
    (void)send_telemetry(HFB_PKT_HOUSEKEEPING_ID, &dev.seq_housekeeping, payload, sizeof payload);
}

void event_send(uint8_t level, uint16_t code, const char *text)
{
    hfb_pkt_event_t ev;
    uint8_t payload[HFB_MAX_PAYLOAD];
    size_t n = strlen(text);
    if (n > HFB_MAX_PAYLOAD - HFB_PKT_EVENT_SIZE) {
        n = HFB_MAX_PAYLOAD - HFB_PKT_EVENT_SIZE;  /* our texts are ASCII: any cut is a boundary */
    }
    ev.level = level;
    ev.code = code;
    ev.text = (const uint8_t *)text;
    ev.text_len = n;
    n = hfb_pkt_event_pack(&ev, payload, sizeof payload);
    /* SPEC 5.3: events go where telemetry goes; with no session, nowhere */
    (void)send_telemetry(HFB_PKT_EVENT_ID, &dev.seq_event, payload, n);
}
