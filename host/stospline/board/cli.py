"""The `board` and `hil` subcommands (registered by `stospline.cli.build_parser`)."""
from __future__ import annotations

import argparse
import os
import re
import stat
import struct
import sys
from dataclasses import replace
from pathlib import Path

from stospline.errors import ProblemError

__all__ = ["add_commands"]

EM_ARM = 40   # e_machine of an ARM ELF file


def _elf(text: str) -> str:
    """An existing 32-bit little-endian ARM ELF file (what QEMU's -kernel loads)."""
    path = Path(text)
    if not text or not path.is_file():
        raise argparse.ArgumentTypeError(f"{text!r} is not a file")
    try:
        with open(path, "rb") as fh:
            head = fh.read(20)
    except OSError as exc:
        raise argparse.ArgumentTypeError(f"cannot read {text}: {exc.strerror}") from None
    if (len(head) < 20 or head[:4] != b"\x7fELF" or head[4] != 1 or head[5] != 1
            or struct.unpack_from("<H", head, 18)[0] != EM_ARM):
        raise argparse.ArgumentTypeError(f"{text} is not a 32-bit ARM ELF image (the "
                                         f"build/qemu/firmware.elf of a `stospline board` "
                                         f"project)")
    return text


def _port(text: str) -> str:
    """``tcp:HOST:PORT`` (PORT 1..65535) or an existing character device."""
    if text.startswith("tcp:"):
        host, sep, num = text[4:].rpartition(":")
        if not (sep and re.fullmatch(r"[0-9]{1,5}", num) and 1 <= int(num) <= 65535
                and re.fullmatch(r"[^\s/]*", host)):
            raise argparse.ArgumentTypeError(f"must be tcp:HOST:PORT with PORT in 1..65535, "
                                             f"got {text!r}")
        return text
    try:
        mode = os.stat(text).st_mode
    except (OSError, ValueError) as exc:
        why = exc.strerror if isinstance(exc, OSError) else str(exc)
        raise argparse.ArgumentTypeError(f"{text!r} is neither tcp:HOST:PORT nor a serial "
                                         f"device: {why}") from None
    if not stat.S_ISCHR(mode):
        raise argparse.ArgumentTypeError(f"{text} is not a serial device (a character device "
                                         f"such as /dev/ttyACM0) nor tcp:HOST:PORT")
    return text


def add_commands(sub, cli) -> None:
    """Add `board` and `hil` to the subparsers `sub`; `cli` is the `stospline.cli` module
    (its option types and design options), passed in so that this module does not import
    it."""
    from stospline.board.project import BOARDS
    integer, out_dir, seed_max = cli._integer, cli._out_dir, cli.SEED_MAX
    p = sub.add_parser("board", help="write a firmware project for a board: start-up, linker "
                                     "script, tick timer, UART frames, tables, CMake presets")
    p.add_argument("problem", help="problem file (TOML)")
    p.add_argument("--board", required=True, choices=sorted(BOARDS),
                   help="the board (a QEMU machine name)")
    p.add_argument("--out", required=True, type=out_dir,
                   help="directory for the project's files (created if missing; all are "
                        "replaced together or not at all)")
    p.add_argument("--arith", default=None, metavar="{float32,q15,q31}",
                   help="arithmetic of the tables (default: the board's)")
    p.add_argument("--ignore-noise", action="store_true",
                   help="design as if there were no noise (the paper's Remark 2)")
    p.add_argument("--timeout-ticks", type=integer(1, 1_000_000), default=1000,
                   help="tick periods without a STATE frame after which the board applies "
                        "u_hold and reports a timeout (default 1000)")
    p.add_argument("--verify-ticks", type=integer(1, 1_000_000), default=1000,
                   help="ticks between two stsp_verify() calls (default 1000)")
    p.set_defaults(func=lambda args: _board(args, cli))

    p = sub.add_parser("hil", help="hardware in the loop: the plant on this host, the "
                                   "controller on a board (or QEMU) over a serial line, one "
                                   "frame per tick")
    p.add_argument("problem", help="problem file (TOML)")
    p.add_argument("--board", required=True, choices=sorted(BOARDS))
    where = p.add_mutually_exclusive_group(required=True)
    where.add_argument("--elf", type=_elf, help="run this image (`stospline board` project, qemu "
                                     "preset) in QEMU and connect to its serial line")
    where.add_argument("--port", type=_port, help="the board's serial line: a device (/dev/ttyACM0) or "
                                      "tcp:HOST:PORT")
    p.add_argument("--paths", type=integer(2, 512), default=100,
                   help="paths through the board, 2..512 (default 100)")
    p.add_argument("--seed", type=integer(0, seed_max), default=1)
    p.add_argument("--substeps", type=integer(1, 10_000), default=1,
                   help="plant steps per controller tick (default 1)")
    p.add_argument("--batch", type=integer(1, 255), default=None,
                   help="paths a frame carries: 1 sends one path's state a tick (STATE "
                        "frames, a real board's loop); b > 1 the states of b paths in one "
                        "BATCH frame, stepped by b controller instances on the board "
                        "(default: as many as the board's HELLO offers)")
    p.add_argument("--arith", default=None, metavar="{float32,q15,q31}",
                   help="the tables' arithmetic on the board (default: the board's)")
    p.add_argument("--ignore-noise", action="store_true")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=lambda args: _hil(args, cli))


def _board(args, cli) -> int:
    from stospline.atomic import check_target
    from stospline.board.project import BOARDS, project_files, write_project
    _check_budget, _limits, _options = cli._check_budget, cli._limits, cli._design_options
    from stospline.pipeline import design_problem, generated_files
    from stospline.problem.reader import load_problem
    board = BOARDS[args.board]
    arith = args.arith or board.arith
    if arith not in ("float32", "q15", "q31"):
        raise ProblemError("--arith", f"must be one of ['float32', 'q15', 'q31'], got {arith!r}")
    check_target(args.out, (), [args.problem])
    problem = load_problem(args.problem)
    opts = replace(_options(args, problem), arith=arith)
    if opts.delay_ticks:
        raise ProblemError(_delay_field(args), "the board project runs tables designed "
                                               "without a delay")
    _check_budget(args, problem, opts, "design", arith=arith)
    d = design_problem(problem, options=opts, **_limits(args))
    tables = generated_files(d, Path(args.problem).name, arith)
    stem = next(k for k in tables if k.endswith(".c"))[:-2]
    from stospline.board.hil import table_of
    table = table_of(d, arith)
    flash = _table_bytes(d.table, arith)
    if flash > board.flash_bytes - 32 * 1024:
        raise ProblemError("--board", f"the {stem} tables take {flash} B of flash; the "
                                      f"{board.name} has {board.flash_bytes} B (less 32 KiB "
                                      f"for the code): lower tick_hz, use --arith q15 or "
                                      f"--table spline")
    files = project_files(Path(args.problem).name, board, table, tables,
                          timeout_ticks=args.timeout_ticks, verify_ticks=args.verify_ticks)
    written = write_project(args.out, files, [args.problem])
    print(f"{board.name} project for {stem} ({table.n_ticks} ticks at {table.tick_hz} Hz, "
          f"{flash} B of tables): {len(written)} files in {args.out}")
    print(f"build: STOSPLINE_PREFIX=<stospline installed for {board.cpu}> cmake --preset qemu "
          f"&& cmake --build --preset qemu   (in {args.out}; README.md)")
    return 0


def _exited(proc, seconds: float = 1.0) -> bool:
    """Whether `proc` ends within `seconds` (a line QEMU closed as it exits)."""
    import subprocess
    try:
        proc.wait(timeout=seconds)
    except subprocess.TimeoutExpired:
        return False
    return True


def _delay_field(args) -> str:
    """Where a delay came from: the command line, or the file's [design] table."""
    return "--delay-ticks" if args.delay_ticks is not None else "design.delay_ticks"


def _table_bytes(table, arith: str) -> int:
    from stospline.table.flash import flash_bytes
    return int(flash_bytes(table, arith))


def _hil(args, cli) -> int:
    from stospline.board import hil
    from stospline.board.project import BOARDS
    _limits, _options = cli._limits, cli._design_options
    from stospline.report.summary_text import simulation_summary_text
    from stospline.pipeline import design_problem, simulation_summary
    from stospline.problem.reader import load_problem
    from stospline.harness.controller import build_controller
    from stospline.harness.montecarlo import simulate
    board = BOARDS[args.board]
    arith = args.arith or board.arith
    if arith not in ("float32", "q15", "q31"):
        raise ProblemError("--arith", f"must be one of ['float32', 'q15', 'q31'], got {arith!r}")
    problem = load_problem(args.problem)
    if problem.faults.any:
        raise ProblemError("faults", "the serial HIL run simulates the fault-free loop; "
                                     "run `stospline simulate` for faults")
    opts = replace(_options(args, problem), arith=arith)
    if opts.delay_ticks:
        raise ProblemError(_delay_field(args), "the board runs tables designed without a "
                                               "delay")
    if any(st.varying is not None for st in problem.stages):
        raise ProblemError("stages", "the serial HIL run needs time-invariant stage data")
    d = design_problem(problem, options=opts, **_limits(args))
    table = hil.table_of(d, arith)
    ctl = build_controller(table)
    ref = simulate(problem, ctl, paths=args.paths, seed=args.seed, substeps=args.substeps,
                   workers=1, record=args.paths, per_path=True)
    # A line that cannot be opened, fails or carries what is not the protocol: exit 2, one
    # line naming the option that chose the line.
    option = "--elf" if args.elf is not None else "--port"
    proc = link = None
    try:
        if args.elf is not None:
            proc, link = hil.start_qemu(board.name, args.elf)
        else:
            link = hil.open_port(args.port)
        try:
            info = hil.hello(link)
        except ValueError as exc:
            raise hil.HilError(f"the board's HELLO frame is not one: {exc}") from None
        if info.crc32 != int(ctl.c_table.crc32) or info.nx != table.dims[0]:
            raise ProblemError("--board", f"the board runs a table with crc32 0x{info.crc32:08X} "
                                          f"({info.arith}), this design's is "
                                          f"0x{int(ctl.c_table.crc32):08X} ({arith}): regenerate "
                                          f"its project with `stospline board`")
        batch = info.batch if args.batch is None else args.batch
        if batch > max(1, info.batch):
            raise ProblemError("--batch", f"the board steps at most {info.batch} paths a "
                                          f"frame, got {batch}")
        res = hil.run_hil(problem, ctl, link, paths=args.paths, seed=args.seed,
                          substeps=args.substeps, reference=ref, batch=batch)
    except hil.HilError as exc:
        why = str(exc)
        if proc is not None and _exited(proc):   # QEMU gave up: the first line it said
            said = proc.stderr.read().decode(errors="replace").strip().splitlines()
            why += f" (qemu-system-arm: {said[0].strip()})" if said else ""
        print(f"stospline: error: {option}: {why}", file=sys.stderr)
        return 2
    except struct.error as exc:
        print(f"stospline: error: {option}: a frame from the board too short for its type "
              f"({exc})", file=sys.stderr)
        return 2
    except OSError as exc:
        if link is None and proc is None and args.elf is not None:
            what = "cannot start qemu-system-arm"
        elif link is None:
            what = f"cannot open {args.port}"
        else:
            what = "the serial line failed"
        print(f"stospline: error: {option}: {what}: {exc.strerror or exc}", file=sys.stderr)
        return 2
    finally:
        if link is not None:
            link.close()
        if proc is not None:
            proc.kill()
            proc.wait()
            proc.stderr.close()
    # The summary is the host run's statistics: the board's paths equal them bit for bit
    # when `mismatches` is 0, and the HIL entry below says so.
    s = simulation_summary(d, ref, seed=args.seed)
    s["hil"] = {"board": board.name, "arith": arith, "seconds": res.seconds, "batch": batch,
                "bit_identical": res.mismatches == 0, "mismatches": res.mismatches,
                "first_mismatch": res.first_mismatch,
                "statuses": {str(k): v for k, v in sorted(res.statuses.items())},
                "board_statuses": {str(k): v for k, v in sorted(res.board_statuses.items())},
                "overruns": res.overruns, "timeouts": res.timeouts,
                "bad_frames_board": res.bad_frames, "lost_frames": res.lost_frames,
                "bad_frames_host": res.host_bad_frames,
                "cycles_per_tick": info.cycles_per_tick, "clock_hz": info.clock_hz}
    print(cli.dumps(s) + "\n" if args.json else simulation_summary_text(s), end="", flush=True)
    if not args.json:
        hs = s["hil"]
        print(f"  HIL on {board.name} ({arith}): {res.paths} paths x {res.ticks} ticks in "
              f"{res.seconds:.1f} s ({batch} a frame, "
              f"{1e3 * res.seconds / (res.paths * res.ticks):.3f} ms a path-tick); commands "
              "and states vs the host-compiled controller: "
              + ("bit-identical" if res.mismatches == 0 else
                 f"{res.mismatches} mismatches, first at (path, tick) {res.first_mismatch}"))
        print(f"  board: overruns {hs['overruns']}, timeouts {hs['timeouts']}, bad frames "
              f"{hs['bad_frames_board']} (host {hs['bad_frames_host']}), lost frames "
              f"{hs['lost_frames']}; statuses {hs['statuses']}")
    return 0 if res.mismatches == 0 else 1
