"""The `board` and `hil` subcommands (registered by `stospline.cli.build_parser`)."""
from __future__ import annotations

import sys
from pathlib import Path

from stospline.errors import ProblemError

__all__ = ["add_commands"]


def add_commands(sub, integer, out_dir, seed_max: int, max_paths: int) -> None:
    """Add `board` and `hil` to the subparsers `sub` (helpers from `stospline.cli`)."""
    from stospline.board.project import BOARDS
    p = sub.add_parser("board", help="write a firmware project for a board: start-up, linker "
                                     "script, SysTick tick, UART frames, tables, CMake presets")
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
    p.set_defaults(func=_board)


def _board(args) -> int:
    from stospline.atomic import check_target
    from stospline.board.project import BOARDS, project_files, write_project
    from stospline.cli import _check_budget, _limits, _options
    from stospline.pipeline import design_problem, generated_files
    from stospline.problem.reader import load_problem
    board = BOARDS[args.board]
    arith = args.arith or board.arith
    if arith not in ("float32", "q15", "q31"):
        raise ProblemError("--arith", f"must be one of ['float32', 'q15', 'q31'], got {arith!r}")
    check_target(args.out, (), [args.problem])
    problem = load_problem(args.problem)
    opts = _options(args, problem)
    if opts["delay_ticks"]:
        raise ProblemError("--delay-ticks", "the board project runs tables designed without "
                                            "a delay")
    _check_budget(args, problem, "design", arith=arith)
    d = design_problem(problem, noise=not args.ignore_noise, **opts, **_limits(args))
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


def _table_bytes(table, arith: str) -> int:
    from stospline.table.flash import flash_bytes
    return int(flash_bytes(table, arith))
