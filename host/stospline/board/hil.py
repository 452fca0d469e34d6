"""Serial hardware-in-the-loop: the host simulates the plant, the board runs the controller.

One frame per tick over a serial line (QEMU's serial on a local socket, or a board's UART):
the host sends the state the controller measures (STATE), the board answers with the command
it applies (COMMAND). The plant is the Monte Carlo harness's (`harness.montecarlo`): the same
integrator in C, the same random numbers for the same seed (block 0 of the seed, paths in the
same order), so a path through the board must equal the host-compiled controller's path bit
for bit; `run_hil` checks that it does, tick by tick.
"""
from __future__ import annotations

import os
import select
import socket
import struct
import subprocess
import time
from dataclasses import dataclass, field

import numpy as np

from stospline.board import frames as fr
from stospline.errors import StosplineError

__all__ = ["table_of", "HilResult", "run_hil", "open_port", "start_qemu", "QEMU_MACHINES"]

QEMU_MACHINES = {"netduinoplus2": "netduinoplus2", "microbit": "microbit"}


def table_of(d, arith: str):
    """The table of arithmetic `arith` the board runs (and the host compares with)."""
    if arith == "float32":
        return d.table
    from stospline.pipeline import fixed_point_spline, fixed_point_table
    if d.table.spline is not None:
        return fixed_point_spline(d, arith)[0]
    return fixed_point_table(d, arith)


class HilError(StosplineError, RuntimeError):
    """The serial line or the board failed (a lost or corrupted answer, a timeout)."""


@dataclass
class HilResult:
    paths: int
    ticks: int
    cost: np.ndarray                    # (paths,) per path, through the board
    knot_states: list                   # per knot (paths, n)
    mismatches: int                     # (path, tick) commands or states not bit-identical
    first_mismatch: tuple | None        # (path, tick) of the first
    statuses: dict = field(default_factory=dict)   # controller status -> count
    board_statuses: dict = field(default_factory=dict)
    overruns: int = 0
    timeouts: int = 0
    bad_frames: int = 0                 # the board's count of bad frames it received
    lost_frames: int = 0
    host_bad_frames: int = 0            # bad frames the host received
    events: int = 0                     # EVENT frames (timeouts) the host skipped
    seconds: float = 0.0


class Link:
    """A byte stream to the board: a connected socket or a serial device's descriptor."""

    def __init__(self, sock=None, fd=None, timeout: float = 5.0):
        self.sock, self.fd, self.timeout = sock, fd, timeout
        self.parser = fr.Parser()
        self.pending: list = []
        self.seq = 0

    def send(self, kind: int, payload: bytes = b"") -> None:
        data = fr.encode(kind, self.seq, payload)
        self.seq = (self.seq + 1) & 0xFF
        if self.sock is not None:
            self.sock.sendall(data)
        else:
            os.write(self.fd, data)

    def recv(self) -> fr.Frame:
        deadline = time.monotonic() + self.timeout
        while not self.pending:
            left = deadline - time.monotonic()
            if left <= 0:
                raise HilError(f"no frame from the board within {self.timeout:g} s")
            src = self.sock if self.sock is not None else self.fd
            ready, _, _ = select.select([src], [], [], left)
            if not ready:
                continue
            data = self.sock.recv(65536) if self.sock is not None else os.read(self.fd, 65536)
            if not data:
                raise HilError("the board closed the serial line")
            self.pending += self.parser.feed(data)
        return self.pending.pop(0)

    def close(self) -> None:
        if self.sock is not None:
            self.sock.close()
        elif self.fd is not None:
            os.close(self.fd)


def open_port(port: str, timeout: float = 5.0) -> Link:
    """``tcp:HOST:PORT`` (e.g. QEMU's ``-serial tcp::PORT,server``) or a serial device
    (raw, 115200 8N1)."""
    if port.startswith("tcp:"):
        host, _, num = port[4:].rpartition(":")
        s = socket.create_connection((host or "127.0.0.1", int(num)), timeout=timeout)
        s.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        return Link(sock=s, timeout=timeout)
    import termios
    import tty
    fd = os.open(port, os.O_RDWR | os.O_NOCTTY)
    try:
        tty.setraw(fd)
        attrs = termios.tcgetattr(fd)
        attrs[4] = attrs[5] = termios.B115200
        termios.tcsetattr(fd, termios.TCSANOW, attrs)
    except termios.error as exc:
        os.close(fd)
        raise HilError(f"{port} is not a serial line: {exc.args[-1]}") from None
    return Link(fd=fd, timeout=timeout)


def start_qemu(board: str, elf: str, timeout: float = 5.0):
    """QEMU running `elf` on `board`, its first serial line connected to a socket this process
    listens on: ``(process, Link)``."""
    srv = socket.socket()
    srv.bind(("127.0.0.1", 0))
    srv.listen(1)
    port = srv.getsockname()[1]
    proc = subprocess.Popen(
        ["qemu-system-arm", "-M", QEMU_MACHINES[board], "-nographic", "-monitor", "none",
         "-kernel", str(elf), "-chardev",
         f"socket,id=s0,host=127.0.0.1,port={port},nodelay=on", "-serial", "chardev:s0"],
        stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    srv.settimeout(20.0)
    try:
        conn, _ = srv.accept()
    except OSError:
        proc.kill()
        err = proc.communicate()[1].decode(errors="replace").strip()
        raise HilError(f"QEMU did not connect its serial line: {err}") from None
    finally:
        srv.close()
    conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
    return proc, Link(sock=conn, timeout=timeout)


def hello(link: Link) -> fr.Hello:
    """Ask the board what it runs (QUERY -> HELLO), skipping anything sent before."""
    link.send(fr.QUERY)
    for _ in range(64):
        f = link.recv()
        if f.kind == fr.HELLO:
            return fr.parse_hello(f.payload)
    raise HilError("the board does not answer QUERY with HELLO")


def run_hil(problem, ctl, link: Link, *, paths: int, seed: int, substeps: int = 1,
            reference=None, batch: int = 1) -> HilResult:
    """`paths` paths of the plant with the board in the loop (block 0 of `seed`: at most
    `montecarlo.BLOCK_PATHS`), compared tick by tick with `reference`, the harness's run of the
    same paths (`montecarlo.simulate(..., record=paths)`). `batch` 1: one path at a time, a
    STATE frame a tick (the loop of a real board); `batch` b > 1 (at most the HELLO's): b paths
    at a time, their states in one BATCH frame a tick, stepped by b controller instances."""
    from stospline.harness.montecarlo import _zoh, block_seed
    table = ctl.table
    n, m = problem.n, problem.m
    arith = getattr(table, "arith", "float32")
    h = 1.0 / table.tick_hz
    dt = h / substeps
    ticks = int(table.n_ticks)
    # The plant's numbers, as the harness draws them: one array (paths, substeps, mz) a tick.
    normals = ctl.normals(block_seed(seed, 0))
    noise, plants = [], []
    for k in range(table.n_stages):
        st = problem.stages[k]
        plants.append(ctl.plant(st, *_zoh(st, dt), dt, substeps))
        dZ = np.empty((paths, substeps, st.G.shape[2]))
        fill = normals(dZ)
        for _ in range(int(table.stage_start[k]), int(table.stage_start[k + 1])):
            fill()
            noise.append(dZ.copy())
    if arith == "float32":
        xcode = ucode = "<f4"
    else:
        F = table.frac_bits
        to_q = np.ldexp(1.0, F - np.asarray(table.x_exp, dtype=int))
        lo, hi = -(1 << F), (1 << F) - 1
        lsb = np.asarray(table.u_lsb, dtype=float)
        xcode = ucode = "<i2" if arith == "q15" else "<i4"
    entry = np.dtype([("st", "i1"), ("u", ucode, (m,))])       # BATCH_COMMANDS, per path
    ubytes = np.dtype(ucode).itemsize * m
    res = HilResult(paths, ticks, np.zeros(paths), [np.empty((paths, n)) for _ in problem.knots],
                    0, None)
    t_start = time.monotonic()
    for p0 in range(0, paths, batch):
        p1 = min(paths, p0 + batch)
        b = p1 - p0
        link.send(fr.RESET)
        while link.recv().kind != fr.HELLO:
            pass
        X = np.repeat(np.asarray(problem.x0, dtype=float).reshape(1, n), b, axis=0)
        cost = np.zeros(b)
        U = np.zeros((b, m), np.float32)
        for k in range(table.n_stages):
            for j in range(int(table.stage_start[k]), int(table.stage_start[k + 1])):
                if arith == "float32":
                    xs = X.astype(xcode).tobytes()
                else:
                    xs = np.clip(np.floor(X * to_q + 0.5), lo, hi).astype(xcode).tobytes()
                if batch == 1:
                    link.send(fr.STATE, struct.pack("<I", j) + xs)
                    want = fr.COMMAND
                else:
                    link.send(fr.BATCH, struct.pack("<IB", j, b) + xs)
                    want = fr.BATCH_COMMANDS
                while True:
                    f = link.recv()
                    if f.kind == want:
                        break
                    res.events += 1
                if batch == 1:
                    tick, st, bst = struct.unpack_from("<IbB", f.payload)
                    sts = (st,)
                    u = np.frombuffer(f.payload, ucode, m, 6)
                    at = 6 + ubytes
                else:
                    tick, got, bst = struct.unpack_from("<IBB", f.payload)
                    if got != b:
                        raise HilError(f"paths {p0}..{p1 - 1}: the board answered {got} "
                                       f"paths to {b}")
                    rec = np.frombuffer(f.payload, entry, b, 6)
                    sts = rec["st"].tolist()
                    u = rec["u"]
                    at = 6 + b * entry.itemsize
                if tick != j:
                    raise HilError(f"path {p0}: the board answered tick {tick} to tick {j}")
                for st in sts:
                    res.statuses[st] = res.statuses.get(st, 0) + 1
                res.board_statuses[bst] = res.board_statuses.get(bst, 0) + 1
                U[:] = u if arith == "float32" else u * lsb
                ctl.plant_tick(plants[k], noise[j][p0:p1], U, X, cost)
                if reference is not None:
                    bad = ((U.view(np.uint32) != reference.record_u[j, p0:p1].view(np.uint32))
                           .any(axis=1)
                           | (X.astype(np.float32).view(np.uint32)
                              != reference.record_x[j + 1, p0:p1].view(np.uint32)).any(axis=1))
                    if bad.any():
                        res.mismatches += int(bad.sum())
                        if res.first_mismatch is None:
                            res.first_mismatch = (p0 + int(np.argmax(bad)), j)
            knot = problem.knots[k]
            if knot.penalty is not None:
                r = X @ knot.penalty.C.T - knot.penalty.target
                cost += knot.penalty.weight * np.einsum("pi,pi->p", r, r)
            res.knot_states[k][p0:p1] = X
        res.cost[p0:p1] = cost
        counters = struct.unpack_from("<4H", f.payload, at)
        res.overruns += counters[0]
        res.timeouts += counters[1]
        res.bad_frames += counters[2]
        res.lost_frames += counters[3]
    res.host_bad_frames = link.parser.bad
    if reference is not None:
        for p in range(paths):
            if reference.cost[p] != res.cost[p] and res.first_mismatch is None:
                res.mismatches += 1
                res.first_mismatch = (p, ticks)
    res.seconds = time.monotonic() - t_start
    return res
