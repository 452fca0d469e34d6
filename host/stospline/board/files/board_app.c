/* The board's controller loop, the same on every board: the stospline controller stepped once
 * per tick, states in and commands out over the UART in frames (stsp_frame.h), the safe
 * command u_hold applied on any error, stsp_verify() at boot, at each RESET and every
 * BOARD_VERIFY_TICKS ticks, and an overrun counter.
 *
 * Two tick sources (board_config.h, BOARD_PACED):
 *   1 (paced, the HIL default, and what QEMU runs): a tick is the arrival of a STATE frame;
 *     the step runs at once and its COMMAND frame goes back. The tick timer still runs at
 *     tick_hz and measures: a step that takes longer than one tick period counts an overrun,
 *     and no STATE frame for BOARD_TIMEOUT_TICKS tick periods during a run applies u_hold and
 *     sends an EVENT frame (BOARD_STATUS_TIMEOUT).
 *   0 (real time): the tick-timer interrupt at tick_hz is the tick: it steps with the newest
 *     STATE frame, which must have arrived since the previous tick (else u_hold,
 *     BOARD_STATUS_TIMEOUT); the COMMAND frame is queued and sent by the main loop.
 * A BATCH frame carries the states of up to BOARD_BATCH paths at one tick: BOARD_BATCH
 * controller instances on the same table step them, one each, and one BATCH_COMMANDS frame
 * answers. It multiplies the paths a serial line carries per second (the HIL throughput in an
 * emulator, whose UART costs per received byte); it drives no actuator.
 * The protocol and the mapping to a real board: docs/guide/board.md. */
#include <stddef.h>
#include <stdint.h>

#include "board.h"
#include "board_config.h"
#include "stsp_frame.h"

/* Board statuses (COMMAND and EVENT frames). */
#define BOARD_STATUS_OK 0u
#define BOARD_STATUS_SEQ_GAP 1u     /* a host frame was lost before this one (seq jumped) */
#define BOARD_STATUS_BAD_FRAME 2u   /* a frame failed its CRC or length: u_hold applied */
#define BOARD_STATUS_BAD_STATE 3u   /* a STATE frame of the wrong length: u_hold applied */
#define BOARD_STATUS_TIMEOUT 4u     /* no STATE frame in time: u_hold applied */
#define BOARD_STATUS_NOT_RUNNING 5u /* a STATE frame before RESET: u_hold applied */
#define BOARD_STATUS_BAD_TYPE 6u    /* a frame of an unknown type: ignored */


#define SCALAR_BYTES ((uint32_t)sizeof(stsp_scalar_t))
#define STATE_PAYLOAD (4u + BOARD_NX * SCALAR_BYTES)
#define COMMAND_PAYLOAD (6u + BOARD_NU * SCALAR_BYTES + 8u)
/* BATCH: tick (u32), b (u8), b states; BATCH_COMMANDS: tick, b, board status, b x (status,
 * nu commands), the counters. */
#define BATCH_PAYLOAD(b) (5u + (b) * BOARD_NX * SCALAR_BYTES)
#define BATCH_ENTRY (1u + BOARD_NU * SCALAR_BYTES)
#define BATCH_COMMANDS_PAYLOAD(b) (6u + (b) * BATCH_ENTRY + 8u)

/* Compile-time check: the table's states and commands fit a frame (STSP_FRAME_MAX_PAYLOAD). */
typedef char board_frames_fit[(STATE_PAYLOAD <= STSP_FRAME_MAX_PAYLOAD &&
                               COMMAND_PAYLOAD <= STSP_FRAME_MAX_PAYLOAD &&
                               BOARD_BATCH >= 1u && BOARD_BATCH <= 255u &&
                               BATCH_PAYLOAD(BOARD_BATCH) <= STSP_FRAME_MAX_PAYLOAD &&
                               BATCH_COMMANDS_PAYLOAD(BOARD_BATCH) <= STSP_FRAME_MAX_PAYLOAD)
                                  ? 1
                                  : -1];

/* ctrl[0] runs the STATE frames; all BOARD_BATCH run a BATCH frame's paths. */
static stsp_ctrl_t ctrl[BOARD_BATCH];
static stsp_frame_parser_t parser;
static stsp_status_t init_status;
static stsp_status_t verify_status;
static int clock_failed;
static int running;
static uint8_t tx_seq;
static uint8_t rx_seq;
static int rx_seq_known;
static uint32_t ticks_since_verify;
/* Counters since the last RESET (saturate at 0xFFFF in the frames). */
static uint32_t overruns, timeouts, bad_frames, lost_frames;
static stsp_scalar_t applied[BOARD_NU];
/* Tick-timer interrupts since boot (BOARD_TIMER_PER_TICK per tick period). */
static volatile uint32_t timer_irqs;
static volatile uint32_t last_state_irq;

static void put_u16(uint8_t *b, uint32_t v)
{
    const uint32_t s = (v > 0xFFFFu) ? 0xFFFFu : v;
    b[0] = (uint8_t)(s & 0xFFu);
    b[1] = (uint8_t)(s >> 8);
}

static void put_scalars(uint8_t *b, const stsp_scalar_t *v, uint32_t n)
{
    uint32_t i, k;
    for (i = 0u; i < n; ++i) {
        const uint8_t *src = (const uint8_t *)&v[i]; /* little-endian cores */
        for (k = 0u; k < SCALAR_BYTES; ++k) {
            b[i * SCALAR_BYTES + k] = src[k];
        }
    }
}

static void get_scalars(stsp_scalar_t *v, const uint8_t *b, uint32_t n)
{
    uint32_t i, k;
    for (i = 0u; i < n; ++i) {
        uint8_t *dst = (uint8_t *)&v[i];
        for (k = 0u; k < SCALAR_BYTES; ++k) {
            dst[k] = b[i * SCALAR_BYTES + k];
        }
    }
}

static void send(uint8_t type, const uint8_t *payload, size_t len)
{
    uint8_t frame[STSP_FRAME_MAX_BYTES];
    const size_t n = stsp_frame_encode(frame, type, tx_seq, payload, len);
    tx_seq = (uint8_t)(tx_seq + 1u);
    board_uart_write(frame, n);
}

/* The safe command: the table's u_hold (what the actuators get on any error). */
static void apply_hold(void)
{
    uint32_t i;
    for (i = 0u; i < BOARD_NU; ++i) {
        applied[i] = BOARD_TABLE.u_hold[i];
    }
}

static void send_hello(void)
{
    uint8_t b[29];
    b[0] = STSP_FRAME_PROTOCOL;
    b[1] = BOARD_ARITH_CODE;
    b[2] = (uint8_t)BOARD_NX;
    b[3] = (uint8_t)BOARD_NU;
    stsp_frame_put_u32(b + 4, BOARD_TABLE.n_ticks);
    stsp_frame_put_u32(b + 8, BOARD_TABLE.tick_hz);
    stsp_frame_put_u32(b + 12, BOARD_TABLE.crc32);
    b[16] = (uint8_t)(int8_t)init_status;
    b[17] = (uint8_t)(int8_t)verify_status;
    b[18] = BOARD_ID;
    b[19] = (uint8_t)((BOARD_PACED ? 1u : 0u) | (clock_failed ? 2u : 0u));
    stsp_frame_put_u32(b + 20, board_clock_hz());
    stsp_frame_put_u32(b + 24, BOARD_CYCLES_PER_TICK);
    b[28] = (uint8_t)BOARD_BATCH;
    send(STSP_FRAME_HELLO, b, sizeof b);
}

static void fill_counters(uint8_t *b)
{
    put_u16(b, overruns);
    put_u16(b + 2, timeouts);
    put_u16(b + 4, bad_frames);
    put_u16(b + 6, lost_frames);
}

static void send_event(uint8_t board_status, stsp_status_t st)
{
    uint8_t b[3u + 8u + BOARD_NU * SCALAR_BYTES];
    b[0] = board_status;
    b[1] = (uint8_t)(int8_t)st;
    b[2] = rx_seq;
    fill_counters(b + 3);
    put_scalars(b + 11, applied, BOARD_NU);
    send(STSP_FRAME_EVENT, b, sizeof b);
}

/* Processor cycles since boot, read consistently with the tick-timer interrupt count. */
static uint32_t cycles_now(void)
{
    uint32_t s0, s1, v;
    s0 = timer_irqs;
    v = board_timer_elapsed();
    s1 = timer_irqs;
    if (s1 != s0) {
        v = board_timer_elapsed();
    }
    return s1 * (BOARD_TIMER_RELOAD + 1u) + v;
}

/* One controller step: the command into u (the table's u_hold on a negative status); a step
 * longer than a tick period counts an overrun. */
static stsp_status_t step_one(stsp_ctrl_t *c, uint32_t tick, const stsp_scalar_t *x,
                              stsp_scalar_t *u)
{
    const uint32_t start = cycles_now();
    const stsp_status_t st = stsp_step(c, tick, x, u);
    uint32_t i;
    if (st < 0) {
        for (i = 0u; i < BOARD_NU; ++i) {
            u[i] = BOARD_TABLE.u_hold[i];
        }
    }
    if (cycles_now() - start > BOARD_CYCLES_PER_TICK) {
        ++overruns;
    }
    return st;
}

/* One tick: step the controller with the state of a STATE frame and answer. */
static void run_tick(uint32_t tick, const stsp_scalar_t *x, uint8_t board_status)
{
    uint8_t b[COMMAND_PAYLOAD];
    stsp_scalar_t u[BOARD_NU];
    uint32_t i;
    const stsp_status_t st = step_one(&ctrl[0], tick, x, u);
    for (i = 0u; i < BOARD_NU; ++i) {
        applied[i] = u[i];
    }
    /* board-specific: write applied[] to the actuators here (a real board's PWM, DAC, ...) */
    stsp_frame_put_u32(b, tick);
    b[4] = (uint8_t)(int8_t)st;
    b[5] = board_status;
    put_scalars(b + 6, applied, BOARD_NU);
    fill_counters(b + 6u + BOARD_NU * SCALAR_BYTES);
    send(STSP_FRAME_COMMAND, b, sizeof b);
    ++ticks_since_verify;
}

/* One tick of b paths: instance i steps the i-th state of a BATCH frame; one answer. */
static void run_batch(uint32_t tick, uint32_t b, uint8_t board_status)
{
    uint8_t out[BATCH_COMMANDS_PAYLOAD(BOARD_BATCH)];
    stsp_scalar_t x[BOARD_NX];
    stsp_scalar_t u[BOARD_NU];
    uint32_t i;
    stsp_frame_put_u32(out, tick);
    out[4] = (uint8_t)b;
    out[5] = board_status;
    for (i = 0u; i < b; ++i) {
        uint8_t *e = out + 6u + i * BATCH_ENTRY;
        get_scalars(x, parser.payload + BATCH_PAYLOAD(i), BOARD_NX);
        e[0] = (uint8_t)(int8_t)step_one(&ctrl[i], tick, x, u);
        put_scalars(e + 1, u, BOARD_NU);
    }
    fill_counters(out + 6u + b * BATCH_ENTRY);
    send(STSP_FRAME_BATCH_COMMANDS, out, BATCH_COMMANDS_PAYLOAD(b));
    ++ticks_since_verify;
}

/* Every instance checks the table and its own copy of the header; the first error counts. */
static void verify_now(void)
{
    uint32_t i;
    verify_status = STSP_OK;
    for (i = 0u; i < BOARD_BATCH; ++i) {
        const stsp_status_t st = stsp_verify(&ctrl[i]);
        if (verify_status == STSP_OK) {
            verify_status = st;
        }
    }
    ticks_since_verify = 0u;
}

static void on_frame(void)
{
    uint8_t board_status = BOARD_STATUS_OK;
    if (rx_seq_known && parser.seq != (uint8_t)(rx_seq + 1u)) {
        ++lost_frames;
        board_status = BOARD_STATUS_SEQ_GAP;
    }
    rx_seq = parser.seq;
    rx_seq_known = 1;
    if (parser.type == STSP_FRAME_QUERY) {
        send_hello();
    } else if (parser.type == STSP_FRAME_RESET) {
        uint32_t i;
        verify_now();
        for (i = 0u; i < BOARD_BATCH; ++i) {
            (void)stsp_reset(&ctrl[i]);
        }
        overruns = timeouts = bad_frames = lost_frames = 0u;
        apply_hold();
        running = 1;
        last_state_irq = timer_irqs;
        send_hello();
    } else if (parser.type == STSP_FRAME_STATE) {
        stsp_scalar_t x[BOARD_NX];
        last_state_irq = timer_irqs;
        if (parser.len != STATE_PAYLOAD) {
            apply_hold();
            send_event(BOARD_STATUS_BAD_STATE, STSP_OK);
        } else if (!running) {
            apply_hold();
            send_event(BOARD_STATUS_NOT_RUNNING, STSP_OK);
        } else {
            get_scalars(x, parser.payload + 4, BOARD_NX);
            run_tick(stsp_frame_get_u32(parser.payload), x, board_status);
            if (ticks_since_verify >= BOARD_VERIFY_TICKS) {
                verify_now(); /* between two ticks: the next STATE frame waits */
            }
        }
    } else if (parser.type == STSP_FRAME_BATCH) {
        const uint32_t b = (parser.len >= 5u) ? parser.payload[4] : 0u;
        last_state_irq = timer_irqs;
        if (b < 1u || b > BOARD_BATCH || parser.len != BATCH_PAYLOAD(b)) {
            send_event(BOARD_STATUS_BAD_STATE, STSP_OK);
        } else if (!running) {
            send_event(BOARD_STATUS_NOT_RUNNING, STSP_OK);
        } else {
            run_batch(stsp_frame_get_u32(parser.payload), b, board_status);
            if (ticks_since_verify >= BOARD_VERIFY_TICKS) {
                verify_now();
            }
        }
    } else {
        send_event(BOARD_STATUS_BAD_TYPE, STSP_OK);
    }
}

void board_timer_handler(void)
{
    timer_irqs = timer_irqs + 1u;
}

int board_main(void)
{
    uint8_t byte;
    uint32_t i;
    clock_failed = board_init();
    stsp_frame_reset(&parser);
    init_status = STSP_OK;
    for (i = 0u; i < BOARD_BATCH; ++i) {
        const stsp_status_t st = stsp_init(&ctrl[i], &BOARD_TABLE);
        if (init_status == STSP_OK) {
            init_status = st;
        }
    }
    verify_now();
    apply_hold();
    board_timer_start(BOARD_TIMER_RELOAD);
    send_hello();
    for (;;) {
        /* At most one frame's worth of bytes per pass, so the timeout check below runs. */
        uint32_t budget = STSP_FRAME_MAX_BYTES;
        while (budget > 0u && board_uart_read(&byte)) {
            const stsp_frame_result_t r = stsp_frame_push(&parser, byte);
            --budget;
            if (r == STSP_FRAME_READY) {
                on_frame();
            } else if (r != STSP_FRAME_MORE) {
                ++bad_frames;
                apply_hold();
                send_event(BOARD_STATUS_BAD_FRAME, STSP_OK);
            }
        }
        if (running && timer_irqs - last_state_irq > BOARD_TIMEOUT_TICKS * BOARD_TIMER_PER_TICK) {
            ++timeouts;
            apply_hold();
            last_state_irq = timer_irqs;
            send_event(BOARD_STATUS_TIMEOUT, STSP_OK);
        }
        if (budget == STSP_FRAME_MAX_BYTES) {
            board_idle();
        }
    }
}
