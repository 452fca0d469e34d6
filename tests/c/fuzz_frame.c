/* libFuzzer target on the board's serial frame parser (host/stospline/board/files/stsp_frame.c;
 * built by CMakeLists.txt with clang, -fsanitize=fuzzer,address,undefined).
 *
 * Each input describes a byte stream as a sequence of chunks: whole frames made by
 * stsp_frame_encode() (any type, seq and payload, length 0..STSP_FRAME_MAX_PAYLOAD), sent intact, with one bit
 * flipped, with one byte dropped, cut short, or with a length byte above the maximum; runs of
 * raw garbage; and runs of sync bytes (0xA5, 0x5A). The parser gets the stream one byte at a
 * time, in a heap block of exactly its size (ASan sees a read or write outside it).
 *
 * Invariants (a broken one aborts, libFuzzer keeps the input):
 *  - every result of stsp_frame_push() is the one of a reference scanner written from the
 *    protocol in stsp_frame.h, not from the parser: find the next 0xA5 0x5A, read type, seq,
 *    len; len > STSP_FRAME_MAX_PAYLOAD is STSP_FRAME_BAD_LEN at the length byte; otherwise the
 *    frame's last byte gives STSP_FRAME_READY when the CRC-16/CCITT-FALSE (a table-driven one
 *    here) of type, seq, len and payload is the received one, STSP_FRAME_BAD_CRC when not;
 *    the scan goes on after the frame. So a frame is accepted iff its length and CRC are right.
 *  - on STSP_FRAME_READY, type, seq, len and the payload are the frame's bytes in the stream;
 *  - an intact encoded frame that starts where the scanner is between frames is accepted;
 *  - resynchronisation: after the stream, STSP_FRAME_MAX_BYTES zero bytes bring the parser
 *    back between frames from wherever it is (no result but STSP_FRAME_MORE, BAD_CRC), and
 *    the next encoded frame is accepted with its own fields;
 *  - stsp_frame_encode() writes exactly len + STSP_FRAME_OVERHEAD bytes, 0 for a length above
 *    the maximum or a NULL pointer, and what it writes matches the reference CRC. */
#include <stddef.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "fuzz_input.h"
#include "stsp_frame.h"

#define STREAM_MAX 4096u

static uint16_t crc_table[256];

/* The table-driven form of CRC-16/CCITT-FALSE (polynomial 0x1021, MSB first). */
static void ref_crc_init(void)
{
    uint32_t i, bit;
    for (i = 0u; i < 256u; ++i) {
        uint32_t c = i << 8;
        for (bit = 0u; bit < 8u; ++bit) {
            c = ((c & 0x8000u) != 0u) ? (((c << 1) ^ 0x1021u) & 0xFFFFu) : ((c << 1) & 0xFFFFu);
        }
        crc_table[i] = (uint16_t)c;
    }
}

static uint16_t ref_crc(const uint8_t *d, size_t n)
{
    uint32_t c = 0xFFFFu;
    size_t i;
    for (i = 0u; i < n; ++i) {
        c = ((c << 8) ^ crc_table[((c >> 8) ^ d[i]) & 0xFFu]) & 0xFFFFu;
    }
    return (uint16_t)c;
}

/* Expected result at each index of the stream; frame_start[i]: where the frame that ends at
 * i started (its first sync byte), for READY. */
static void reference(const uint8_t *s, size_t n, int8_t *expect, size_t *frame_start,
                      uint8_t *between)
{
    size_t i = 0u;
    size_t k;
    for (k = 0u; k < n; ++k) {
        expect[k] = STSP_FRAME_MORE;
        between[k] = 0u;
    }
    while (i < n) {
        size_t j = i;
        size_t len, end;
        between[i] = 1u;
        while (j + 1u < n && !(s[j] == STSP_FRAME_SYNC0 && s[j + 1u] == STSP_FRAME_SYNC1)) {
            ++j;
            between[j] = 1u;
        }
        if (j + 4u >= n) {
            return; /* no complete header left */
        }
        len = s[j + 4u];
        if (len > STSP_FRAME_MAX_PAYLOAD) {
            expect[j + 4u] = STSP_FRAME_BAD_LEN;
            i = j + 5u;
            continue;
        }
        end = j + 6u + len; /* the CRC's second byte */
        if (end >= n) {
            return;
        }
        expect[end] = (int8_t)((ref_crc(s + j + 2u, 3u + len) ==
                                (uint16_t)(s[end - 1u] | (uint16_t)(s[end] << 8)))
                                   ? STSP_FRAME_READY
                                   : STSP_FRAME_BAD_CRC);
        frame_start[end] = j;
        i = end + 1u;
    }
}

/* Appends an encoded frame (maybe damaged) to the stream; returns its start or SIZE_MAX. */
static size_t add_frame(fuzz_in_t *in, uint8_t *s, size_t *n, uint8_t *intact)
{
    uint8_t payload[STSP_FRAME_MAX_PAYLOAD];
    uint8_t frame[STSP_FRAME_MAX_BYTES];
    const uint8_t type = (uint8_t)fuzz_u8(in);
    const uint8_t seq = (uint8_t)fuzz_u8(in);
    const size_t len = fuzz_u8(in) % (STSP_FRAME_MAX_PAYLOAD + 1u);
    const uint32_t damage = fuzz_u8(in);
    size_t i, size, start;
    for (i = 0u; i < len; ++i) {
        payload[i] = (uint8_t)fuzz_u8(in);
    }
    size = stsp_frame_encode(frame, type, seq, payload, len);
    fuzz_check(size == len + STSP_FRAME_OVERHEAD);
    fuzz_check(frame[0] == STSP_FRAME_SYNC0 && frame[1] == STSP_FRAME_SYNC1 && frame[2] == type &&
               frame[3] == seq && frame[4] == len && memcmp(frame + 5, payload, len) == 0);
    fuzz_check(ref_crc(frame + 2, 3u + len) == (uint16_t)(frame[5u + len] | (frame[6u + len] << 8)));
    switch (damage % 8u) {
    case 1u: /* one bit flipped */
        i = fuzz_u8(in) % size;
        frame[i] = (uint8_t)(frame[i] ^ (1u << (fuzz_u8(in) % 8u)));
        break;
    case 2u: /* one byte dropped */
        i = fuzz_u8(in) % size;
        memmove(frame + i, frame + i + 1u, size - i - 1u);
        --size;
        break;
    case 3u: /* cut short */
        size = fuzz_u8(in) % size;
        break;
    case 4u: /* a length above the maximum */
        frame[4] = (uint8_t)(STSP_FRAME_MAX_PAYLOAD + 1u + fuzz_u8(in) % (255u - STSP_FRAME_MAX_PAYLOAD));
        break;
    default:
        break;
    }
    if (*n + size > STREAM_MAX) {
        return SIZE_MAX;
    }
    start = *n;
    memcpy(s + *n, frame, size);
    *n += size;
    *intact = (uint8_t)((damage % 8u) == 0u || (damage % 8u) >= 5u);
    return start;
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    static uint8_t stream[STREAM_MAX];
    static int8_t expect[STREAM_MAX];
    static size_t frame_start[STREAM_MAX];
    static uint8_t between[STREAM_MAX];
    static size_t intact_starts[STREAM_MAX];
    fuzz_in_t in = {data, size};
    size_t n = 0u, n_intact = 0u, i, k;
    stsp_frame_parser_t *p;
    uint8_t *heap;
    uint8_t out[STSP_FRAME_MAX_BYTES + 1u];
    uint8_t last[4] = {0x11u, 0x22u, 0x33u, 0x44u};
    size_t last_n;
    size_t pos;
    uint8_t intact = 0u;

    ref_crc_init();
    /* encode's refusals: nothing written. */
    memset(out, 0xEE, sizeof out);
    fuzz_check(stsp_frame_encode(out, 1u, 2u, out, STSP_FRAME_MAX_PAYLOAD + 1u) == 0u);
    fuzz_check(stsp_frame_encode(NULL, 1u, 2u, out, 0u) == 0u);
    fuzz_check(stsp_frame_encode(out, 1u, 2u, NULL, 1u) == 0u);
    for (i = 0u; i < sizeof out; ++i) {
        fuzz_check(out[i] == 0xEEu);
    }
    fuzz_check(stsp_frame_push(NULL, 0u) == STSP_FRAME_NULL);

    while (in.n > 0u && n < STREAM_MAX) {
        const uint32_t op = fuzz_u8(&in);
        const size_t run = fuzz_u8(&in) % 64u;
        if (op % 4u == 0u) {
            const size_t start = add_frame(&in, stream, &n, &intact);
            if (start == SIZE_MAX) {
                break;
            }
            if (intact != 0u) {
                intact_starts[n_intact++] = start;
            }
        } else if (op % 4u == 1u) { /* garbage */
            for (k = 0u; k < run && n < STREAM_MAX; ++k) {
                stream[n++] = (uint8_t)fuzz_u8(&in);
            }
        } else if (op % 4u == 2u) { /* sync bytes, in any order */
            for (k = 0u; k < run && n < STREAM_MAX; ++k) {
                stream[n++] = (uint8_t)((fuzz_u8(&in) & 1u) ? STSP_FRAME_SYNC0 : STSP_FRAME_SYNC1);
            }
        } else { /* a few raw bytes */
            for (k = 0u; k < (run % 8u) && n < STREAM_MAX; ++k) {
                stream[n++] = (uint8_t)fuzz_u8(&in);
            }
        }
    }
    reference(stream, n, expect, frame_start, between);

    /* The parser in a heap block of its own size; the stream copied to one of exactly n. */
    p = malloc(sizeof *p);
    heap = malloc(n > 0u ? n : 1u);
    fuzz_check(p != NULL && heap != NULL);
    memcpy(heap, stream, n);
    memset(p, 0xCD, sizeof *p); /* reset must not depend on what was there */
    stsp_frame_reset(p);
    for (i = 0u; i < n; ++i) {
        const stsp_frame_result_t r = stsp_frame_push(p, heap[i]);
        fuzz_check((int)r == (int)expect[i]);
        if (r == STSP_FRAME_READY) {
            const size_t j = frame_start[i];
            fuzz_check(p->type == heap[j + 2u] && p->seq == heap[j + 3u] &&
                       p->len == heap[j + 4u] && i == j + 6u + p->len &&
                       memcmp(p->payload, heap + j + 5u, p->len) == 0);
        }
    }
    /* Every intact frame that starts between frames is accepted (its last byte is READY). */
    for (k = 0u; k < n_intact; ++k) {
        const size_t j = intact_starts[k];
        const size_t end = j + 6u + heap[j + 4u];
        if (between[j] != 0u && end < n) {
            fuzz_check(expect[end] == STSP_FRAME_READY && frame_start[end] == j);
        }
    }
    /* Resynchronisation: zeros end whatever frame is open, then a frame is accepted. */
    for (i = 0u; i < STSP_FRAME_MAX_BYTES; ++i) {
        const stsp_frame_result_t r = stsp_frame_push(p, 0u);
        fuzz_check(r == STSP_FRAME_MORE || r == STSP_FRAME_BAD_CRC || r == STSP_FRAME_READY);
    }
    stsp_frame_put_u32(last, fuzz_u32(&in));
    fuzz_check(stsp_frame_get_u32(last) == ((uint32_t)last[0] | ((uint32_t)last[1] << 8) |
                                            ((uint32_t)last[2] << 16) | ((uint32_t)last[3] << 24)));
    last_n = fuzz_u8(&in) % (sizeof last + 1u);
    last_n = stsp_frame_encode(out, 0x53u, 0x7Fu, last, last_n);
    for (pos = 0u; pos < last_n; ++pos) {
        const stsp_frame_result_t r = stsp_frame_push(p, out[pos]);
        fuzz_check(r == ((pos + 1u == last_n) ? STSP_FRAME_READY : STSP_FRAME_MORE));
    }
    fuzz_check(p->type == 0x53u && p->seq == 0x7Fu && p->len == last_n - STSP_FRAME_OVERHEAD &&
               memcmp(p->payload, last, p->len) == 0);
    free(heap);
    free(p);
    return 0;
}
