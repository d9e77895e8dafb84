"""The filter's vocabulary, in one place: what a call did, why it fell back, which solver answered.

Codes are what the compiled pipeline writes into a result record (RESULT_DTYPE, `filter.pipeline`);
names are what people read (filter_status, reports, the CLI). Both come from the tuples below, so a
code and its name cannot drift apart. The configurable choices (fallback policy, solver, backup
solver) are configuration vocabulary, named once in `config.schema`; their codes are their positions.
"""

from __future__ import annotations

from rta_attitude.config.schema import BACKUP_SOLVERS, FALLBACKS, SOLVERS

STATUS_NAMES: tuple[str, ...] = ("pass", "solved", "fallback")
"""A call's status: `pass` (u_des clipped to the box already met every row: no solve), `solved` (the
QP moved u), `fallback` (the QP failed, or the input was not usable)."""
PASS, SOLVED, FALLBACK = range(len(STATUS_NAMES))

FALLBACK_REASONS: tuple[str, ...] = ("", "non_finite_u_des", "policy", "invalid_state", "output_guard")
"""Why a call fell back: not at all; u_des had non-finite entries (taken as 0); the QP failed (the
configured policy acted); the state was not usable (u = 0); the filter node's last check replaced an
output that was not finite or not inside U by u = 0 (never expected: the core guarantees it)."""
NO_FALLBACK, NON_FINITE_U_DES, POLICY_ACTED, INVALID_STATE, OUTPUT_GUARD = range(len(FALLBACK_REASONS))

PASS_THROUGH, HOLD, SOFTEN, RAISE, PRIORITIZE = (
    FALLBACKS.index(n) for n in ("pass_through", "hold", "soften", "raise", "prioritize"))
"""Codes of the fallback policies (`filter.fallback`): pass_through (u_des clipped to the box, the paper),
hold (u = 0 clipped to the box), soften (the QP again with every row slacked: the least-violation
command), raise (SolverError), prioritize (the levels of `filter.priorities` give way least important
first, each by as little as possible)."""
ACTIVE_SET, PROXSUITE = (SOLVERS.index(n) for n in ("active_set", "proxsuite"))
"""Codes of the QP solvers (`filter.solver`): the exact dual active-set method (compiled), proxsuite."""
QUADPROG, NO_BACKUP = (BACKUP_SOLVERS.index(n) for n in ("quadprog", "none"))
"""Codes of the re-solvers of a QP proxsuite missed (`filter.backup_solver`)."""

GATE_NAMES: tuple[str, ...] = ("off", "verified", "backup", "unverified", "toward_backup", "filtered_backup")
"""What the gatekeeper did (`filter.gatekeeper`): no backup law configured; the filter's answer passed the
check (a hold of it, then the backup law, safe over the horizon) and was applied; the backup law was
applied (the answer failed the check; the plan verified earlier, or the backup law's own command
just checked, goes on); neither the answer nor the backup law passed and no plan remained (the answer
was applied unverified); the same, but a variant of the backup law stayed safe longer in its rollout
than the answer did in any of its own, so the filter answered that variant's command instead of u_des
(the ASIF's answer to it was applied, unverified: docs/backup.md, "When nothing verifies"); neither the
answer nor the backup law passed, but the backup law filtered by the ASIF (the filter's answer to the law's
command at every sample of the rollout) did, and its first command was applied (docs/backup.md, "The backup
law through the filter"; the following calls on its plan apply its commands as 'backup')."""
GATE_OFF, GATE_VERIFIED, GATE_BACKUP, GATE_UNVERIFIED, GATE_TOWARD_BACKUP, GATE_FILTERED_BACKUP = range(len(GATE_NAMES))

SOLVE_RESULTS: tuple[str, ...] = ("solved", "infeasible", "max_iter", "check_failed")
"""What one QP solve ended in: optimal and checked; infeasible; out of iterations; a claimed solution
that failed the check against the rows (or, for proxsuite, the KKT conditions)."""
SOLVE_OK, SOLVE_INFEASIBLE, SOLVE_MAX_ITER, SOLVE_CHECK_FAILED = range(len(SOLVE_RESULTS))
NOT_SOLVED = -1
"""Solver code of a call that did not solve a QP."""


def solve_text(solver: int, result: int, backup: int = NOT_SOLVED) -> str:
    """'active_set:solved', 'proxsuite:max_iter>quadprog:solved', ... ('' when no QP was solved)."""
    if result == NOT_SOLVED:
        return ""
    text = f"{SOLVERS[solver]}:{SOLVE_RESULTS[result]}"
    if backup != NOT_SOLVED:
        text += f">quadprog:{SOLVE_RESULTS[backup]}"
    return text


__all__ = [
    "ACTIVE_SET", "FALLBACK", "FALLBACK_REASONS", "GATE_BACKUP", "GATE_FILTERED_BACKUP", "GATE_NAMES", "GATE_OFF",
    "GATE_TOWARD_BACKUP",
    "GATE_UNVERIFIED", "GATE_VERIFIED", "HOLD", "INVALID_STATE", "NON_FINITE_U_DES", "NOT_SOLVED",
    "NO_BACKUP", "NO_FALLBACK", "OUTPUT_GUARD", "PASS", "PASS_THROUGH", "POLICY_ACTED", "PRIORITIZE", "PROXSUITE",
    "QUADPROG",
    "RAISE", "SOFTEN", "SOLVED", "SOLVE_CHECK_FAILED", "SOLVE_INFEASIBLE", "SOLVE_MAX_ITER", "SOLVE_OK",
    "SOLVE_RESULTS", "STATUS_NAMES", "solve_text",
]  # fmt: skip
