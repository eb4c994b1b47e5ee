/*
 * version_probe.c - SPEC 7: "A device that receives a COMMAND frame with another major
 * version, whose payload (bytes 4-5) holds the CONNECT opcode, should answer REJECTED
 * DICTIONARY_MISMATCH", in a frame of its own version, so the host can tell its
 * operator which side to update.
 *
 * The kit's deframer drops such a frame as a version error before any handler sees it
 * (SPEC 4.1 rule 2), so this file looks at the same bytes beside it: a candidate with
 * the sync word, another version byte, packet id COMMAND, a complete span and a good
 * CRC (the header, the COMMAND payload and CONNECT's arguments keep their layout in
 * every major version, SPEC 7).  The CRC makes a false match in ordinary traffic as
 * unlikely as an undetected frame error.
 */
#include <string.h>

#include "device.h"

static void answer(int c, const uint8_t *frame, size_t length)
{
    hfb_cmd_connect_reply_t reply;
    uint8_t data[HFB_CMD_CONNECT_REPLY_SIZE];
    (void)length;
    reply.session_token = 0u;
    reply.protocol_major = HFB_PROTOCOL_VERSION_MAJOR;
    reply.protocol_minor = HFB_PROTOCOL_VERSION_MINOR;
    reply.dictionary_hash = HFB_DICTIONARY_HASH;
    reply.tick = dev.tick;
    (void)hfb_cmd_connect_reply_pack(&reply, data, sizeof data);
    respond(c, hfb_get_u32(frame + HFB_HDR_SEQUENCE_OFFSET), HFB_CMD_CONNECT_OPCODE,
            HFB_PKT_RESPONSE_STAGE_REJECTED, HFB_ERR_DICTIONARY_MISMATCH, data, sizeof data);
}

/* scan what is buffered; return how many bytes can be forgotten */
static size_t scan(int c, const uint8_t *b, size_t n)
{
    size_t i = 0;
    while (i + HFB_HEADER_SIZE <= n) {
        size_t length, total;
        if (b[i] != HFB_SYNC_0 || b[i + 1] != HFB_SYNC_1 || b[i + 2] == HFB_PROTOCOL_VERSION_MAJOR
            || b[i + 3] != HFB_PKT_COMMAND_ID) {
            i++;
            continue;
        }
        length = hfb_get_u16(b + i + HFB_HDR_LENGTH_OFFSET);
        if (length < HFB_PKT_COMMAND_SIZE || length > HFB_MAX_PAYLOAD) {
            i++;
            continue;
        }
        total = length + HFB_FRAME_OVERHEAD;
        if (i + total > n) {
            return i;                              /* wait for the rest of it */
        }
        if (hfb_crc32(b + i, total) == HFB_CRC_RESIDUE
            && hfb_get_u16(b + i + HFB_HEADER_SIZE + HFB_PKT_COMMAND_OPCODE_OFFSET) == HFB_CMD_CONNECT_OPCODE) {
            answer(c, b + i, total);
            i += total;
            continue;
        }
        i++;
    }
    return i;
}

void version_probe_feed(int c, const uint8_t *data, size_t n)
{
    connection_t *k = &dev.conn[c];
    while (n > 0u) {
        size_t room = sizeof k->probe - k->probe_len;
        size_t take = n < room ? n : room;
        size_t drop;
        memcpy(k->probe + k->probe_len, data, take);
        k->probe_len += take;
        data += take;
        n -= take;
        drop = scan(c, k->probe, k->probe_len);
        /* keep a waiting candidate, but never more than one largest frame */
        if (k->probe_len - drop > HFB_MAX_FRAME) {
            drop = k->probe_len - HFB_MAX_FRAME;
        }
        memmove(k->probe, k->probe + drop, k->probe_len - drop);
        k->probe_len -= drop;
    }
}
