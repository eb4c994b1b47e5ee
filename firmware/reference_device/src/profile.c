/*
 * profile.c - playback of SPEC 11.2: sample validity per target, which mode plays which
 * target, and the per-period step (SPEC 10.1 step 4).
 *
 * Sample-exact: in the k-th period after PROFILE_START (k = 1, 2, ...) sample k-1 drives
 * the target and HIGH_RATE shows profile_index = k.  PROFILE_START runs between two
 * periods, so the very next period is k = 1.
 */
#include <math.h>

#include "device.h"

int profile_sample_valid(uint8_t target, float v)
{
    if (!isfinite(v)) {
        return 0;
    }
    switch (target) {
    case HFB_CMD_PROFILE_BEGIN_ARGS_TARGET_REFERENCE:
        return v >= HFB_CMD_SET_REFERENCE_ARGS_REFERENCE_MIN && v <= HFB_CMD_SET_REFERENCE_ARGS_REFERENCE_MAX;
    case HFB_CMD_PROFILE_BEGIN_ARGS_TARGET_RATE_REFERENCE:
        return fabs((double)v) <= GYRO_FULL_SCALE;
    case HFB_CMD_PROFILE_BEGIN_ARGS_TARGET_CURRENT_COARSE:
        return v >= HFB_CMD_SET_CURRENTS_ARGS_CURRENT_COARSE_MIN && v <= HFB_CMD_SET_CURRENTS_ARGS_CURRENT_COARSE_MAX;
    case HFB_CMD_PROFILE_BEGIN_ARGS_TARGET_CURRENT_FINE:
        return v >= HFB_CMD_SET_CURRENTS_ARGS_CURRENT_FINE_MIN && v <= HFB_CMD_SET_CURRENTS_ARGS_CURRENT_FINE_MAX;
    default:
        return 0;
    }
}

int profile_target_plays_in_mode(uint8_t target, uint8_t mode)
{
    switch (target) {
    case HFB_CMD_PROFILE_BEGIN_ARGS_TARGET_REFERENCE:
        return mode == HFB_PKT_HIGH_RATE_MODE_RELATIVE || mode == HFB_PKT_HIGH_RATE_MODE_INERTIAL;
    case HFB_CMD_PROFILE_BEGIN_ARGS_TARGET_RATE_REFERENCE:
        return mode == HFB_PKT_HIGH_RATE_MODE_INERTIAL;
    default:
        return mode == HFB_PKT_HIGH_RATE_MODE_OPEN_LOOP;
    }
}

void profile_start(void)
{
    dev.profile_playing = 1;
    dev.profile_next = 0;                 /* a start during playback restarts at sample 0 */
    dev.profile_delay = (dev.deviations & DEV_PROFILE_LATE) ? 1u : 0u;
    event_send(HFB_PKT_EVENT_LEVEL_INFO, HFB_EVT_PROFILE_STARTED, "profile started");
}

/* Stop playback; the target holds its last value.  The event is PROFILE_STOPPED only for
   PROFILE_STOP itself: a stop because of a disarm carries that cause's event. */
void profile_stop(int send_event)
{
    if (!dev.profile_playing) {
        return;
    }
    dev.profile_playing = 0;
    if (send_event) {
        event_send(HFB_PKT_EVENT_LEVEL_INFO, HFB_EVT_PROFILE_STOPPED, "profile stopped");
    }
}

void profile_step(void)
{
    float v;
    dev.profile_index_shown = 0;          /* 0 in a period that plays no sample */
    if (!dev.profile_playing || !dev.armed || dev.profile == NULL) {
        return;
    }
    if (dev.profile_delay > 0u) {         /* --deviate profile-late only */
        dev.profile_delay--;
        return;
    }
    v = hfb_get_f32(dev.profile + 4u * dev.profile_next);
    switch (dev.profile_target) {
    case HFB_CMD_PROFILE_BEGIN_ARGS_TARGET_REFERENCE: dev.reference = v; break;
    case HFB_CMD_PROFILE_BEGIN_ARGS_TARGET_RATE_REFERENCE: dev.rate_reference = v; break;
    case HFB_CMD_PROFILE_BEGIN_ARGS_TARGET_CURRENT_COARSE: dev.current_cmd_coarse = v; break;
    default: dev.current_cmd_fine = v; break;
    }
    dev.profile_next++;
    dev.profile_index_shown = dev.profile_next;       /* 1-based */
    if (dev.profile_next >= dev.profile_count) {
        dev.profile_playing = 0;                       /* the target holds the last value */
        event_send(HFB_PKT_EVENT_LEVEL_INFO, HFB_EVT_PROFILE_FINISHED, "profile finished");
    }
}
