"""How wide a `linkd design` search runs for its time budget: rounds, atlas paths, designs
refined. A longer budget widens the search rather than lengthening it: wider rounds reach
basins that longer ones around the same few designs do not.
"""

from __future__ import annotations

BUDGET_STEP = 30.0  # seconds: the default budget, the unit a longer one widens the search by
DEFAULT_ROUNDS = 6  # refinement rounds in the default budget: the first and five that grow the
# best designs (drawn shapes, two seeds: three rounds 0.0275 in 11 s, five 0.0247 in 17 s; six,
# once the dyads' backward was written out, 0.0244 in 17.5 s)
STROKE_ROUNDS = 8  # on an open or timed stroke: its copies are placed more slowly, but it has no
# polish (open letters, two seeds: one round 0.1019 in 15 s, three 0.0666 in 17 s; on a machine
# 1.4 times faster, three 0.0461 in 12 s, six 0.0367 in 18 s, and with its first round no wider
# than a loop's, eight 0.0297 in 17 s)
AROUND = 4  # designs a later round searches around, for each 30 s of the budget
FIRST_SHARE = 0.5  # of the time left for refinement, the most the first round may take where
# later rounds follow: on a slow or busy machine it would otherwise take all of it (on one 2.4
# times slower than the one these widths were set on, open letters 0.1078 to 0.0910, closed
# shapes 0.0336 to 0.0319; on that one it took about 30 % on closed shapes, 47 % on strokes)


def search_width(
    time_budget: float,
    rounds: int | None,
    atlas_paths: int | None,
    refine_count: int | None = None,
    stroke: bool = False,
) -> tuple[int, int, int]:
    """Refinement rounds, atlas paths and designs refined in the first round for the time
    budget, where not given: DEFAULT_ROUNDS rounds, 1024 paths and 48 designs for the default
    30 s; for every further 30 s, 1024 paths and 16 designs more (each round also searches
    around more designs, `around_width`) and up to eight rounds more, as many as the budget's
    deadline leaves time for. The deadline also stops refinement early on a slow or busy
    machine. An open or timed `stroke` has STROKE_ROUNDS."""
    steps = budget_steps(time_budget)
    more = 8 * (steps - 1)
    count = refine_count or 16 * (2 + steps)
    rounds = rounds or (STROKE_ROUNDS if stroke else DEFAULT_ROUNDS) + more
    return rounds, atlas_paths or 1024 * steps, count


def around_width(time_budget: float, around: int | None) -> int:
    """Designs each later round searches around, where not given: AROUND for each 30 s of the
    budget (a longer budget's many rounds reach more basins from more starts: 120 s, 16)."""
    return around or AROUND * budget_steps(time_budget)


def budget_steps(time_budget: float) -> int:
    """The budget in units of the default 30 s (at least one): what the search widens by."""
    return max(1, round(time_budget / BUDGET_STEP))
