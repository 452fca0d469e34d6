"""Which designer a problem takes, from its constraints and the options: one place that
dispatches over regions at every tick, band constraints, the exact zero-order-hold design
and the continuous-time one."""
from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

from stospline.design.bands import design_bands, has_bands
from stospline.design.zoh import design_zoh
from stospline.errors import DesignError
from stospline.options import DISCRETIZATIONS, DesignOptions
from stospline.problem.model import Problem
from stospline.table.format import TickGains

if TYPE_CHECKING:
    from stospline.refine.every_tick import EveryTick

# The designers of rarer problems (regions at every tick, the continuous-time design) load
# when a problem needs them: the command line starts faster without them.

__all__ = ["DesignedLaw", "design"]


@dataclass(frozen=True)
class DesignedLaw:
    """A designer's result: `gains` the law the table is made of."""
    gains: TickGains
    # The problem the tables are for: the input, or for regions at every tick the input plus
    # the working set's band knots (its tick regions kept, so it says what it was made for).
    problem: Problem
    # The law the oracle evaluates for a continuous discretization: the continuous-time
    # design (a band design's base law).
    continuous: TickGains
    every_tick: EveryTick | None = None
    # Bands or regions with runtime parameters: the parametric design whose band rows hold
    # over the box (`stospline.oracle.parametric.ParametricDesign`, its margins there).
    over_box: object = None


def design(problem: Problem, options: DesignOptions) -> DesignedLaw:
    """Design `problem` with the method its constraints need; DesignError (naming the field)
    when the options cannot meet them."""
    if problem.parameters and has_bands(problem):
        return _over_box(problem, options)
    if problem.tick_regions:
        return _every_tick(problem, options)
    if has_bands(problem):
        return _bands(problem, options)
    if options.discretization == "exact-zoh":
        gains = design_zoh(problem, noise=options.noise, mode=options.mode,
                           delay_ticks=options.delay_ticks)
    elif options.discretization == "continuous":
        from stospline.design.continuous import design_continuous
        gains = design_continuous(problem, noise=options.noise, mode=options.mode)
    else:
        raise ValueError(f"discretization must be one of {DISCRETIZATIONS}")
    return DesignedLaw(gains, problem, gains)


def _every_tick(problem: Problem, options: DesignOptions) -> DesignedLaw:
    first = f"regions[{problem.tick_regions[0].index}].every"
    if options.mode != "joint":
        raise DesignError(first, 'a region at every tick is a band: use mode joint '
                                 '(--mode joint)')
    if options.discretization != "exact-zoh":
        raise DesignError(first, 'a region at every tick is met for the law held over '
                                 'each tick: use --discretization exact-zoh')
    from stospline.refine.every_tick import design_every_tick
    every_tick = design_every_tick(problem, noise=options.noise)
    return DesignedLaw(every_tick.design, every_tick.problem, every_tick.design, every_tick)


def _over_box(problem: Problem, options: DesignOptions) -> DesignedLaw:
    """Bands or regions with runtime parameters: the nominal of the design whose band rows
    hold over the whole box (`stospline.oracle.parametric`), the regions checked at every
    tick as for any tick-grid design."""
    from stospline.oracle.parametric import design_parametric
    pd = design_parametric(problem, discretization=options.discretization, mode=options.mode,
                           delay_ticks=options.delay_ticks or 0, noise=options.noise)
    every_tick = None
    if problem.tick_regions:
        from stospline.refine.every_tick import tick_grid
        every_tick = tick_grid(problem, noise=options.noise, design=pd.design)
    return DesignedLaw(pd.design, problem, pd.design, every_tick, pd)


def _bands(problem: Problem, options: DesignOptions) -> DesignedLaw:
    if options.mode != "joint":
        raise DesignError("knots", "band constraints (lower/upper) are exact only with one "
                                   "multiplier vector for all knots: use mode joint "
                                   "(--mode joint)")
    if options.discretization not in DISCRETIZATIONS:
        raise ValueError(f"discretization must be one of {DISCRETIZATIONS}")
    gains = design_bands(problem, discretization=options.discretization, noise=options.noise)
    return DesignedLaw(gains, problem, gains.base)
