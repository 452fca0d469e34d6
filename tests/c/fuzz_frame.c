/* libFuzzer target: the board's serial frame parser (host/stospline/board/files/stsp_frame.c,
 * built by CMakeLists.txt with clang, -fsanitize=fuzzer,address,undefined; the tests
 * fuzz_frame and fuzz_frame_long run it).
 *
 * Each input is a byte stream fed to the parser one byte at a time (ASan sees any access past
 * the parser's payload buffer), then, without a reset, STSP_FRAME_MAX_BYTES zero bytes and a
 * valid frame whose type, seq and payload the input's last bytes choose.
 *
 * Invariants (any broken one aborts): a byte returns MORE, READY, BAD_CRC or BAD_LEN; READY
 * only when the bytes just consumed are a whole valid frame (sync, type, seq, len <= the
 * maximum, the payload, the CRC-16/CCITT-FALSE of type, seq, len and payload) that the parser
 * reports field for field; BAD_LEN only on a length above the maximum; after any stream and
 * one frame's worth of non-sync bytes the parser returns READY on the last byte of the valid
 * frame, with its fields (it resynchronises within one frame), and stsp_frame_encode writes
 * exactly that frame (or nothing for a payload above the maximum). */
#include <stddef.h>
#include <stdint.h>
#include <string.h>

#include "fuzz_input.h"
#include "stsp_frame.h"

static stsp_frame_parser_t parser;

/* A whole valid frame ends at hist[n - 1] and the parser holds its fields. */
static int frame_ends_here(const uint8_t *hist, size_t n)
{
    size_t len;
    uint16_t crc;
    if (n < STSP_FRAME_OVERHEAD) {
        return 0;
    }
    len = parser.len;
    if (len > STSP_FRAME_MAX_PAYLOAD || n < len + STSP_FRAME_OVERHEAD) {
        return 0;
    }
    hist += n - (len + STSP_FRAME_OVERHEAD);
    crc = stsp_frame_crc16(0xFFFFu, hist + 2, 3u + len);
    return hist[0] == STSP_FRAME_SYNC0 && hist[1] == STSP_FRAME_SYNC1 &&
           hist[2] == parser.type && hist[3] == parser.seq && hist[4] == len &&
           memcmp(hist + 5, parser.payload, len) == 0 && hist[5 + len] == (crc & 0xFFu) &&
           hist[6 + len] == (crc >> 8);
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);
int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    uint8_t frame[STSP_FRAME_MAX_BYTES];
    uint8_t payload[STSP_FRAME_MAX_PAYLOAD + 1u];
    size_t i, n;
    fuzz_in_t in;
    stsp_frame_result_t r = STSP_FRAME_MORE;
    uint8_t type, seq;
    uint32_t head;
    size_t len;

    stsp_frame_reset(&parser);
    fuzz_check(stsp_frame_push(NULL, 0u) == STSP_FRAME_NULL);
    for (i = 0u; i < size; ++i) {
        r = stsp_frame_push(&parser, data[i]);
        fuzz_check(r == STSP_FRAME_MORE || r == STSP_FRAME_READY || r == STSP_FRAME_BAD_CRC ||
                   r == STSP_FRAME_BAD_LEN);
        if (r == STSP_FRAME_READY) {
            fuzz_check(frame_ends_here(data, i + 1u));
        } else if (r == STSP_FRAME_BAD_LEN) {
            fuzz_check(data[i] > STSP_FRAME_MAX_PAYLOAD);
        }
    }

    /* The valid frame: the input's last bytes choose it (all of them may be the stream's). */
    in.p = (size > 4u + STSP_FRAME_MAX_PAYLOAD) ? data + size - (4u + STSP_FRAME_MAX_PAYLOAD)
                                                : data;
    in.n = (size > 4u + STSP_FRAME_MAX_PAYLOAD) ? 4u + STSP_FRAME_MAX_PAYLOAD : size;
    head = fuzz_u32(&in);
    type = (uint8_t)(head & 0xFFu);
    seq = (uint8_t)((head >> 8) & 0xFFu);
    len = ((head >> 16) & 0xFFu) % (STSP_FRAME_MAX_PAYLOAD + 2u); /* one above the maximum */
    for (i = 0u; i < len; ++i) {
        payload[i] = (uint8_t)fuzz_u8(&in);
    }
    n = stsp_frame_encode(frame, type, seq, payload, len);
    if (len > STSP_FRAME_MAX_PAYLOAD) {
        fuzz_check(n == 0u);
        len = 0u;
        n = stsp_frame_encode(frame, type, seq, payload, 0u);
    }
    fuzz_check(n == len + STSP_FRAME_OVERHEAD);
    fuzz_check(stsp_frame_encode(NULL, type, seq, payload, len) == 0u);

    for (i = 0u; i < STSP_FRAME_MAX_BYTES; ++i) {
        (void)stsp_frame_push(&parser, 0u);
    }
    for (i = 0u; i < n; ++i) {
        r = stsp_frame_push(&parser, frame[i]);
        fuzz_check(r == (i + 1u == n ? STSP_FRAME_READY : STSP_FRAME_MORE));
    }
    fuzz_check(parser.type == type && parser.seq == seq && parser.len == len &&
               memcmp(parser.payload, payload, len) == 0);
    return 0;
}
