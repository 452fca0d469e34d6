/* stospline serial frame protocol: one frame per controller tick between a plant (the host)
 * and the board. Portable C99, no allocation, no recursion; every loop is bounded by a frame.
 *
 * A frame on the wire (all multi-byte fields little-endian):
 *
 *     0xA5 0x5A | type (1) | seq (1) | len (1) | payload (len <= STSP_FRAME_MAX_PAYLOAD) | crc (2)
 *
 * crc is CRC-16/CCITT-FALSE (polynomial 0x1021, initial 0xFFFF, no reflection, no final xor)
 * over type, seq, len and the payload. The parser resynchronises on the next 0xA5 0x5A after
 * any bad byte: a corrupted byte fails the CRC (or the length check), a lost byte makes the
 * frame fail the CRC or run into the next frame's sync, and a lost frame shows as a gap in
 * seq. Frame types and payloads: docs/guide/board.md, "Frame protocol". */
#ifndef STSP_FRAME_H
#define STSP_FRAME_H

#include <stddef.h>
#include <stdint.h>

#define STSP_FRAME_SYNC0 0xA5u
#define STSP_FRAME_SYNC1 0x5Au
#define STSP_FRAME_MAX_PAYLOAD 252u
#define STSP_FRAME_OVERHEAD 7u /* sync (2), type, seq, len, crc (2) */
#define STSP_FRAME_MAX_BYTES (STSP_FRAME_MAX_PAYLOAD + STSP_FRAME_OVERHEAD)
#define STSP_FRAME_PROTOCOL 2u

/* Frame types. Host to board: */
#define STSP_FRAME_QUERY 0x51u /* 'Q': empty; the board answers HELLO */
#define STSP_FRAME_RESET 0x52u /* 'R': empty; verify the table, reset the controller (a new run) */
#define STSP_FRAME_STATE 0x53u /* 'S': tick (u32), then nx states (the table's scalar type) */
#define STSP_FRAME_BATCH 0x42u /* 'B': tick (u32), b (u8), then b x nx states */
/* Board to host: */
#define STSP_FRAME_HELLO 0x48u   /* 'H': what the board runs (board_app.c, send_hello) */
#define STSP_FRAME_COMMAND 0x43u /* 'C': the answer to a STATE frame (board_app.c) */
#define STSP_FRAME_EVENT 0x45u   /* 'E': a board status without a state (timeout, bad frame) */
#define STSP_FRAME_BATCH_COMMANDS 0x44u /* 'D': the answer to a BATCH frame (board_app.c) */

/* What stsp_frame_push() reports for one byte. */
typedef enum {
    STSP_FRAME_MORE = 0,      /* the byte was taken; no frame is complete yet */
    STSP_FRAME_READY = 1,     /* a frame with a good CRC is complete in the parser */
    STSP_FRAME_BAD_CRC = -1,  /* a frame ended with a wrong CRC: dropped */
    STSP_FRAME_BAD_LEN = -2,  /* a length above STSP_FRAME_MAX_PAYLOAD: dropped */
    STSP_FRAME_NULL = -3      /* a NULL parser */
} stsp_frame_result_t;

typedef struct {
    uint8_t state;  /* private: where in a frame the next byte goes */
    uint8_t type;
    uint8_t seq;
    uint8_t len;
    uint16_t got;   /* payload bytes received */
    uint16_t crc;   /* received CRC, while it arrives */
    uint8_t payload[STSP_FRAME_MAX_PAYLOAD];
} stsp_frame_parser_t;

/* CRC-16/CCITT-FALSE of n bytes, continuing from crc (0xFFFF to start). */
uint16_t stsp_frame_crc16(uint16_t crc, const uint8_t *data, size_t n);

/* Empty the parser (it then waits for a sync). */
void stsp_frame_reset(stsp_frame_parser_t *p);

/* Feed one received byte. After STSP_FRAME_READY, type, seq, len and payload hold the frame
 * until the next call. */
stsp_frame_result_t stsp_frame_push(stsp_frame_parser_t *p, uint8_t byte);

/* Write a frame of `len` payload bytes into out (room for len + STSP_FRAME_OVERHEAD bytes).
 * Returns the frame's length, or 0 (nothing written) when len > STSP_FRAME_MAX_PAYLOAD or a
 * pointer is NULL (payload may be NULL when len is 0). */
size_t stsp_frame_encode(uint8_t *out, uint8_t type, uint8_t seq, const uint8_t *payload,
                         size_t len);

/* Little-endian field helpers. */
static inline void stsp_frame_put_u32(uint8_t *b, uint32_t v)
{
    b[0] = (uint8_t)(v & 0xFFu);
    b[1] = (uint8_t)((v >> 8) & 0xFFu);
    b[2] = (uint8_t)((v >> 16) & 0xFFu);
    b[3] = (uint8_t)((v >> 24) & 0xFFu);
}

static inline uint32_t stsp_frame_get_u32(const uint8_t *b)
{
    return (uint32_t)b[0] | ((uint32_t)b[1] << 8) | ((uint32_t)b[2] << 16) |
           ((uint32_t)b[3] << 24);
}

#endif /* STSP_FRAME_H */
