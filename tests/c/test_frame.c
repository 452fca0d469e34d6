/* Unit tests of the board's serial frame protocol (host/stospline/board/files/stsp_frame.c):
 * the CRC, the encoder's layout and refusals, and every status of stsp_frame_push(). The
 * fuzz_frame target checks the parser against a reference scanner on arbitrary streams. */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <string.h>

#include <cmocka.h>

#include "stsp_frame.h"

/* Pushes n bytes; every result but the last must be MORE; returns the last. */
static stsp_frame_result_t push_all(stsp_frame_parser_t *p, const uint8_t *b, size_t n)
{
    size_t i;
    stsp_frame_result_t r = STSP_FRAME_MORE;
    for (i = 0u; i < n; ++i) {
        r = stsp_frame_push(p, b[i]);
        if (i + 1u < n) {
            assert_int_equal(r, STSP_FRAME_MORE);
        }
    }
    return r;
}

static void test_crc16_check_value(void **state)
{
    static const uint8_t check[] = "123456789";
    (void)state;
    /* The catalogued check value of CRC-16/CCITT-FALSE. */
    assert_int_equal(stsp_frame_crc16(0xFFFFu, check, 9u), 0x29B1u);
    /* In pieces, the same. */
    assert_int_equal(stsp_frame_crc16(stsp_frame_crc16(0xFFFFu, check, 4u), check + 4, 5u),
                     0x29B1u);
    assert_int_equal(stsp_frame_crc16(0x1234u, NULL, 5u), 0x1234u);
    assert_int_equal(stsp_frame_crc16(0x1234u, check, 0u), 0x1234u);
}

static void test_encode_layout(void **state)
{
    static const uint8_t payload[3] = {1u, 2u, 3u};
    uint8_t out[STSP_FRAME_MAX_BYTES];
    uint16_t crc;
    (void)state;
    assert_int_equal(stsp_frame_encode(out, STSP_FRAME_STATE, 9u, payload, 3u), 10u);
    assert_int_equal(out[0], 0xA5u);
    assert_int_equal(out[1], 0x5Au);
    assert_int_equal(out[2], STSP_FRAME_STATE);
    assert_int_equal(out[3], 9u);
    assert_int_equal(out[4], 3u);
    assert_memory_equal(out + 5, payload, 3u);
    crc = stsp_frame_crc16(0xFFFFu, out + 2, 6u);
    assert_int_equal(out[8], crc & 0xFFu); /* little-endian */
    assert_int_equal(out[9], crc >> 8);
    /* An empty frame, payload NULL. */
    assert_int_equal(stsp_frame_encode(out, STSP_FRAME_QUERY, 0u, NULL, 0u), STSP_FRAME_OVERHEAD);
}

static void test_encode_refusals_write_nothing(void **state)
{
    uint8_t payload[STSP_FRAME_MAX_PAYLOAD + 1u];
    uint8_t out[STSP_FRAME_MAX_BYTES + 1u];
    uint8_t zeros[sizeof out];
    (void)state;
    memset(payload, 7, sizeof payload);
    memset(out, 0, sizeof out);
    memset(zeros, 0, sizeof zeros);
    assert_int_equal(stsp_frame_encode(out, 1u, 1u, payload, STSP_FRAME_MAX_PAYLOAD + 1u), 0u);
    assert_int_equal(stsp_frame_encode(NULL, 1u, 1u, payload, 1u), 0u);
    assert_int_equal(stsp_frame_encode(out, 1u, 1u, NULL, 1u), 0u);
    assert_memory_equal(out, zeros, sizeof out);
    /* The maximum is allowed. */
    assert_int_equal(stsp_frame_encode(out, 1u, 1u, payload, STSP_FRAME_MAX_PAYLOAD),
                     STSP_FRAME_MAX_BYTES);
}

static void test_push_null(void **state)
{
    (void)state;
    assert_int_equal(stsp_frame_push(NULL, 0xA5u), STSP_FRAME_NULL);
    stsp_frame_reset(NULL); /* defined: nothing happens */
}

static void test_ready_with_fields(void **state)
{
    uint8_t payload[STSP_FRAME_MAX_PAYLOAD];
    uint8_t frame[STSP_FRAME_MAX_BYTES];
    stsp_frame_parser_t p;
    size_t len, n, i;
    (void)state;
    for (i = 0u; i < sizeof payload; ++i) {
        payload[i] = (uint8_t)(i * 37u + 1u);
    }
    stsp_frame_reset(&p);
    /* Back to back: 0, 1, 4 and the maximum payload length. */
    for (len = 0u; len <= STSP_FRAME_MAX_PAYLOAD; len += (len < 4u) ? 1u : STSP_FRAME_MAX_PAYLOAD - 4u) {
        n = stsp_frame_encode(frame, STSP_FRAME_COMMAND, (uint8_t)len, payload, len);
        assert_int_equal(push_all(&p, frame, n), STSP_FRAME_READY);
        assert_int_equal(p.type, STSP_FRAME_COMMAND);
        assert_int_equal(p.seq, (uint8_t)len);
        assert_int_equal(p.len, len);
        if (len > 0u) {
            assert_memory_equal(p.payload, payload, len);
        }
    }
}

static void test_bad_crc_then_resync(void **state)
{
    static const uint8_t payload[2] = {0x10u, 0x20u};
    uint8_t frame[STSP_FRAME_MAX_BYTES];
    stsp_frame_parser_t p;
    size_t n, i;
    (void)state;
    n = stsp_frame_encode(frame, STSP_FRAME_STATE, 1u, payload, 2u);
    for (i = 2u; i < n; ++i) { /* a flipped bit anywhere after the sync */
        uint8_t bad[STSP_FRAME_MAX_BYTES];
        memcpy(bad, frame, n);
        bad[i] = (uint8_t)(bad[i] ^ 0x01u);
        stsp_frame_reset(&p);
        if (i == 4u) { /* the length: the frame ends elsewhere (3 payload bytes) */
            assert_int_equal(push_all(&p, bad, n), STSP_FRAME_MORE);
            assert_int_equal(stsp_frame_push(&p, 0u), STSP_FRAME_BAD_CRC);
        } else {
            assert_int_equal(push_all(&p, bad, n), STSP_FRAME_BAD_CRC);
        }
        /* The next good frame is taken. */
        assert_int_equal(push_all(&p, frame, n), STSP_FRAME_READY);
        assert_int_equal(p.seq, 1u);
    }
}

static void test_bad_len(void **state)
{
    uint8_t frame[STSP_FRAME_MAX_BYTES];
    const uint8_t head[5] = {0xA5u, 0x5Au, STSP_FRAME_STATE, 0u, STSP_FRAME_MAX_PAYLOAD + 1u};
    stsp_frame_parser_t p;
    size_t n;
    (void)state;
    stsp_frame_reset(&p);
    assert_int_equal(push_all(&p, head, 5u), STSP_FRAME_BAD_LEN);
    /* Dropped at once: the next frame follows directly. */
    n = stsp_frame_encode(frame, STSP_FRAME_QUERY, 5u, NULL, 0u);
    assert_int_equal(push_all(&p, frame, n), STSP_FRAME_READY);
    assert_int_equal(p.seq, 5u);
    assert_int_equal(push_all(&p, head, 4u), STSP_FRAME_MORE);
    assert_int_equal(stsp_frame_push(&p, 0xFFu), STSP_FRAME_BAD_LEN);
}

static void test_sync_after_garbage(void **state)
{
    static const uint8_t garbage[] = {0x00u, 0x5Au, 0xA5u, 0x00u, 0xA5u, 0xA5u, 0xA5u};
    uint8_t frame[STSP_FRAME_MAX_BYTES];
    stsp_frame_parser_t p;
    size_t n;
    (void)state;
    stsp_frame_reset(&p);
    /* Garbage ending in repeated 0xA5: the last 0xA5 still starts the sync. */
    assert_int_equal(push_all(&p, garbage, sizeof garbage), STSP_FRAME_MORE);
    n = stsp_frame_encode(frame, STSP_FRAME_RESET, 3u, NULL, 0u);
    assert_int_equal(push_all(&p, frame + 1, n - 1u), STSP_FRAME_READY);
    assert_int_equal(p.type, STSP_FRAME_RESET);
}

static void test_reset_drops_open_frame(void **state)
{
    static const uint8_t payload[4] = {1u, 2u, 3u, 4u};
    uint8_t frame[STSP_FRAME_MAX_BYTES];
    stsp_frame_parser_t p;
    size_t n;
    (void)state;
    n = stsp_frame_encode(frame, STSP_FRAME_STATE, 2u, payload, 4u);
    stsp_frame_reset(&p);
    assert_int_equal(push_all(&p, frame, 7u), STSP_FRAME_MORE);
    stsp_frame_reset(&p);
    /* The rest of the open frame is garbage now (no sync in it), then a whole frame. */
    assert_int_equal(push_all(&p, frame + 7, n - 7u), STSP_FRAME_MORE);
    assert_int_equal(push_all(&p, frame, n), STSP_FRAME_READY);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_crc16_check_value),
        cmocka_unit_test(test_encode_layout),
        cmocka_unit_test(test_encode_refusals_write_nothing),
        cmocka_unit_test(test_push_null),
        cmocka_unit_test(test_ready_with_fields),
        cmocka_unit_test(test_bad_crc_then_resync),
        cmocka_unit_test(test_bad_len),
        cmocka_unit_test(test_sync_after_garbage),
        cmocka_unit_test(test_reset_drops_open_frame),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
