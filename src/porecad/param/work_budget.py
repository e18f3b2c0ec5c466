"""A work budget for the untangling: seconds counted by a model of the work done, not by the clock."""

from __future__ import annotations

__all__ = ["WorkBudget", "charged"]

#: modelled seconds per element sample-node product (an energy evaluation's Jacobians and their gradient, or a
#: trial's Jacobians); fitted with the other two to the descents and searches of the curved bone (8×8×8 hex8
#: and hex20, from its STL) and the bunny (hex20) on the 2-core runner: within 10 % of the measured seconds (a
#: 3×3×3 grid, whose evaluations are mostly Python overhead, takes up to twice its modelled seconds)
SECONDS_PER_UNIT = 5.5e-9
#: modelled seconds per node of an energy evaluation (assembly, face maps, the L-BFGS-B step)
SECONDS_PER_NODE = 1.7e-6
#: modelled seconds per trial of the local search (its Python overhead), on top of its units
SECONDS_PER_TRIAL = 5e-5


class WorkBudget:
    """Seconds of untangling, counted by a model of the work (not by the clock).

    Each energy evaluation and each trial of the local search is charged
    what it costs on a typical machine (:data:`SECONDS_PER_UNIT`,
    :data:`SECONDS_PER_NODE`, :data:`SECONDS_PER_TRIAL`, measured on this
    project's 2-core runner), so where the untangling stops — and so the grid
    and the scaffold — depends on the input alone, not on the machine or its
    load (a wall-clock limit gave the curved bone's 8×8×8 hex20 grid 16 or 436
    crossing pairs, depending on what else ran).
    """

    def __init__(self, seconds: float):
        self.left = float(seconds)

    def charge(self, units: float = 0.0, nodes: int = 0, trials: int = 0) -> None:
        self.left -= units * SECONDS_PER_UNIT + nodes * SECONDS_PER_NODE + trials * SECONDS_PER_TRIAL

    @property
    def spent(self) -> bool:
        return self.left <= 0.0


def charged(budget, elems, *Ds) -> None:
    """Charge ``budget`` (None: nothing) for the Jacobians of ``elems`` at the samples of each ``D``."""
    if budget is not None:
        budget.charge(units=float(len(elems)) * sum(D.shape[0] * D.shape[2] for D in Ds))
