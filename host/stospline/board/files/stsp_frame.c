/* stospline serial frame protocol: see stsp_frame.h. */
#include "stsp_frame.h"

enum {
    WAIT_SYNC0 = 0,
    WAIT_SYNC1 = 1,
    WAIT_TYPE = 2,
    WAIT_SEQ = 3,
    WAIT_LEN = 4,
    WAIT_PAYLOAD = 5,
    WAIT_CRC0 = 6,
    WAIT_CRC1 = 7
};

uint16_t stsp_frame_crc16(uint16_t crc, const uint8_t *data, size_t n)
{
    size_t i;
    unsigned bit;
    if (data == NULL) {
        return crc;
    }
    for (i = 0u; i < n; ++i) {
        crc = (uint16_t)(crc ^ (uint16_t)((uint16_t)data[i] << 8));
        for (bit = 0u; bit < 8u; ++bit) {
            if ((crc & 0x8000u) != 0u) {
                crc = (uint16_t)((uint16_t)(crc << 1) ^ 0x1021u);
            } else {
                crc = (uint16_t)(crc << 1);
            }
        }
    }
    return crc;
}

void stsp_frame_reset(stsp_frame_parser_t *p)
{
    if (p != NULL) {
        p->state = WAIT_SYNC0;
        p->got = 0u;
        p->len = 0u;
        p->crc = 0u;
    }
}

static uint16_t frame_crc(const stsp_frame_parser_t *p)
{
    uint8_t head[3];
    head[0] = p->type;
    head[1] = p->seq;
    head[2] = p->len;
    return stsp_frame_crc16(stsp_frame_crc16(0xFFFFu, head, 3u), p->payload, p->len);
}

stsp_frame_result_t stsp_frame_push(stsp_frame_parser_t *p, uint8_t byte)
{
    if (p == NULL) {
        return STSP_FRAME_NULL;
    }
    switch (p->state) {
    case WAIT_SYNC0:
        if (byte == STSP_FRAME_SYNC0) {
            p->state = WAIT_SYNC1;
        }
        return STSP_FRAME_MORE;
    case WAIT_SYNC1:
        /* A repeated 0xA5 may itself be the start of the sync. */
        p->state = (byte == STSP_FRAME_SYNC1) ? (uint8_t)WAIT_TYPE
                   : (byte == STSP_FRAME_SYNC0) ? (uint8_t)WAIT_SYNC1
                                                : (uint8_t)WAIT_SYNC0;
        return STSP_FRAME_MORE;
    case WAIT_TYPE:
        p->type = byte;
        p->state = WAIT_SEQ;
        return STSP_FRAME_MORE;
    case WAIT_SEQ:
        p->seq = byte;
        p->state = WAIT_LEN;
        return STSP_FRAME_MORE;
    case WAIT_LEN:
        if (byte > STSP_FRAME_MAX_PAYLOAD) {
            p->state = WAIT_SYNC0;
            return STSP_FRAME_BAD_LEN;
        }
        p->len = byte;
        p->got = 0u;
        p->state = (byte == 0u) ? (uint8_t)WAIT_CRC0 : (uint8_t)WAIT_PAYLOAD;
        return STSP_FRAME_MORE;
    case WAIT_PAYLOAD:
        p->payload[p->got] = byte;
        p->got = (uint16_t)(p->got + 1u);
        if (p->got >= p->len) {
            p->state = WAIT_CRC0;
        }
        return STSP_FRAME_MORE;
    case WAIT_CRC0:
        p->crc = byte;
        p->state = WAIT_CRC1;
        return STSP_FRAME_MORE;
    case WAIT_CRC1:
        p->crc = (uint16_t)(p->crc | (uint16_t)((uint16_t)byte << 8));
        p->state = WAIT_SYNC0;
        return (p->crc == frame_crc(p)) ? STSP_FRAME_READY : STSP_FRAME_BAD_CRC;
    default:
        p->state = WAIT_SYNC0;
        return STSP_FRAME_MORE;
    }
}

size_t stsp_frame_encode(uint8_t *out, uint8_t type, uint8_t seq, const uint8_t *payload,
                         size_t len)
{
    size_t i;
    uint16_t crc;
    if (out == NULL || len > STSP_FRAME_MAX_PAYLOAD || (payload == NULL && len > 0u)) {
        return 0u;
    }
    out[0] = STSP_FRAME_SYNC0;
    out[1] = STSP_FRAME_SYNC1;
    out[2] = type;
    out[3] = seq;
    out[4] = (uint8_t)len;
    for (i = 0u; i < len; ++i) {
        out[5u + i] = payload[i];
    }
    crc = stsp_frame_crc16(0xFFFFu, out + 2, 3u + len);
    out[5u + len] = (uint8_t)(crc & 0xFFu);
    out[6u + len] = (uint8_t)(crc >> 8);
    return len + STSP_FRAME_OVERHEAD;
}
