"""The serial frame protocol, host side (the board's is ``files/stsp_frame.c``).

``0xA5 0x5A | type | seq | len | payload | crc16`` (little-endian fields), crc16 the
CRC-16/CCITT-FALSE of type, seq, len and payload; docs/guide/board.md, "Frame protocol".
"""
from __future__ import annotations

import binascii
import struct
from dataclasses import dataclass

__all__ = ["crc16", "encode", "Parser", "Frame", "QUERY", "RESET", "STATE", "HELLO",
           "COMMAND", "EVENT", "BATCH", "BATCH_COMMANDS", "Hello", "parse_hello",
           "MAX_PAYLOAD", "BOARD_STATUS"]

SYNC = b"\xa5\x5a"
MAX_PAYLOAD = 252
PROTOCOL = 2
QUERY, RESET, STATE, BATCH = 0x51, 0x52, 0x53, 0x42
HELLO, COMMAND, EVENT, BATCH_COMMANDS = 0x48, 0x43, 0x45, 0x44
BOARD_STATUS = {0: "ok", 1: "seq-gap", 2: "bad-frame", 3: "bad-state", 4: "timeout",
                5: "not-running", 6: "bad-type"}
ARITH_NAMES = {0: "float32", 1: "q15", 2: "q31"}


def crc16(data: bytes, crc: int = 0xFFFF) -> int:
    """CRC-16/CCITT-FALSE (polynomial 0x1021, initial 0xFFFF): binascii's CRC-CCITT (XMODEM's
    polynomial, unreflected) started at 0xFFFF."""
    return binascii.crc_hqx(data, crc)


def encode(kind: int, seq: int, payload: bytes = b"") -> bytes:
    if len(payload) > MAX_PAYLOAD:
        raise ValueError(f"a frame's payload is at most {MAX_PAYLOAD} bytes, got {len(payload)}")
    body = bytes((kind, seq & 0xFF, len(payload))) + payload
    return SYNC + body + struct.pack("<H", crc16(body))


@dataclass(frozen=True)
class Frame:
    kind: int
    seq: int
    payload: bytes


class Parser:
    """Bytes in, frames out; bad frames (CRC, length) are counted in `bad` and skipped."""

    def __init__(self):
        self.buf = bytearray()
        self.bad = 0

    def feed(self, data: bytes) -> list[Frame]:
        self.buf += data
        out = []
        while True:
            i = self.buf.find(SYNC)
            if i < 0:
                del self.buf[:max(0, len(self.buf) - 1)]
                return out
            del self.buf[:i]
            if len(self.buf) < 5:
                return out
            n = self.buf[4]
            if n > MAX_PAYLOAD:
                self.bad += 1
                del self.buf[:2]
                continue
            if len(self.buf) < 7 + n:
                return out
            body = bytes(self.buf[2:5 + n])
            (crc,) = struct.unpack_from("<H", self.buf, 5 + n)
            if crc != crc16(body):
                self.bad += 1
                del self.buf[:2]
                continue
            del self.buf[:7 + n]
            out.append(Frame(body[0], body[1], body[3:]))


@dataclass(frozen=True)
class Hello:
    protocol: int
    arith: str
    nx: int
    nu: int
    n_ticks: int
    tick_hz: int
    crc32: int
    init_status: int
    verify_status: int
    board_id: int
    paced: bool
    clock_failed: bool
    clock_hz: int
    cycles_per_tick: int
    batch: int                  # paths a BATCH frame carries at most


def parse_hello(payload: bytes) -> Hello:
    if len(payload) != 29:
        raise ValueError(f"a HELLO frame has 29 payload bytes, got {len(payload)}")
    (proto, arith, nx, nu, n_ticks, tick_hz, crc, init_st, ver_st, board, flags, clock,
     cycles, batch) = struct.unpack("<BBBBIIIbbBBIIB", payload)
    return Hello(proto, ARITH_NAMES.get(arith, f"unknown ({arith})"), nx, nu, n_ticks,
                 tick_hz, crc, init_st, ver_st, board, bool(flags & 1), bool(flags & 2), clock,
                 cycles, batch)
