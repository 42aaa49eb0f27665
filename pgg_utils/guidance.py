"""The training guidance γ_train, once for both training scripts: its flags, its schedule over training
(the one function the rollout, the loss, the diagnostics, the checkpoint and resume read it from), and
whether the null embedding is in the objective at all. Plain Python: no torch, no gymnasium."""

import math
from dataclasses import dataclass
from typing import Literal

SCHEDULES = ("constant", "linear", "adaptive")
# The adaptive rule moves the guidance strength s = γ_train - 1 by at most this factor per iteration, as
# PPO's adaptive-KL variant doubles or halves its penalty: s grows while the guided policy stays within
# the KL target of the conditional one, and shrinks when guidance pushes it further away.
ADAPTIVE_STEP = 1.5


@dataclass
class GuidanceArgs:
    """PGG's training arguments, shared by both training scripts."""

    guidance: float = 1.0
    """guidance strength γ_train of rollouts and updates (1 = PPO; the paper trains with 1.1); with a schedule, its first value"""
    guidance_schedule: Literal[SCHEDULES] = "constant"
    """how γ_train moves over training: constant; linear from --guidance to --guidance-final; adaptive: held near a KL target (pgg_utils/guidance.py)"""
    guidance_final: float | None = None
    """with --guidance-schedule linear: γ_train at the last iteration"""
    guidance_kl_target: float | None = None
    """with --guidance-schedule adaptive: the KL(guided || conditional policy) at which γ_train is held"""
    guidance_bounds: tuple[float, float] = (1.0, 1.5)
    """with --guidance-schedule adaptive: the range γ_train is kept in"""
    cond_dropout: float = 0.0
    """probability that a sample's actor input is replaced by the null embedding during updates"""
    null_bc_coef: float = 0.0
    """behaviour cloning of the rollout's actions by the unconditional branch: the coefficient of their mean -log pi(a|null) in the loss (0: off, the paper's)"""
    null_bc_route: Literal["null", "actor"] = "null"
    """with --null-bc-coef: what the cloning term trains, the null embedding alone (the actor's weights held for it) or the null embedding and the shared actor"""


def uses_null_branch(args) -> bool:
    """Whether PGG puts the unconditional branch pi(.|null) in the objective: guidance other than 1 at
    some iteration, conditioning dropout, or behaviour cloning by it. When it does not, the actor runs PPO's own pass; the
    null embedding then trains only where another term of the loss reads it (reads_parameter)."""
    if args.cond_dropout > 0 or args.guidance_schedule == "adaptive" or args.null_bc_coef > 0:
        return True
    final = args.guidance_final if args.guidance_schedule == "linear" else args.guidance
    return args.guidance != 1.0 or final != 1.0


def reads_parameter(loss, parameter) -> bool:
    """Whether the autograd graph of `loss` (a tensor) reaches `parameter`, a leaf (None: there is none):
    whether the objective reads it at all, whatever its gradient's value. Walks the graph; computes nothing."""
    seen, stack = set(), [loss.grad_fn] if parameter is not None else []
    while stack:
        node = stack.pop()
        if node is None or node in seen:
            continue
        seen.add(node)
        if getattr(node, "variable", None) is parameter:  # AccumulateGrad: the leaf it accumulates into
            return True
        stack.extend(next_node for next_node, _ in node.next_functions)
    return False


class GuidanceSchedule:
    """γ_train of each iteration (1-based, of `num_iterations`):
    - constant: --guidance throughout;
    - linear: from --guidance at the first iteration to --guidance-final at the last;
    - adaptive: starts at --guidance; after each update, `observe(kl)` multiplies the strength s = γ - 1
      by ADAPTIVE_STEP when KL(pi_hat || pi(.|s)) on the rollout's observations (the logged
      `pgg/kl_guided_vs_conditional`) is below
      target / ADAPTIVE_STEP, divides it when the KL is above target · ADAPTIVE_STEP, and keeps γ
      within --guidance-bounds. Its state (the current γ) travels in the checkpoint for resume."""

    def __init__(self, args, num_iterations: int):
        self.kind, self.num_iterations = args.guidance_schedule, num_iterations
        self.start, self.final = args.guidance, args.guidance_final
        self.kl_target, self.bounds = args.guidance_kl_target, tuple(args.guidance_bounds)
        self.current = args.guidance  # the adaptive rule's state

    def value(self, iteration: int) -> float:
        """γ_train of `iteration` (its rollout and its update)."""
        if self.kind == "linear":
            fraction = (iteration - 1) / max(self.num_iterations - 1, 1)
            return self.start + fraction * (self.final - self.start)
        if self.kind == "adaptive":
            return self.current
        return self.start

    def observe(self, stats: dict) -> None:
        """The adaptive rule's step after an update, from the iteration's logged statistics (a no-op
        for the other schedules)."""
        if self.kind != "adaptive" or not math.isfinite(kl := stats["pgg/kl_guided_vs_conditional"]):
            return
        strength = self.current - 1.0
        if kl > self.kl_target * ADAPTIVE_STEP:
            strength /= ADAPTIVE_STEP
        elif kl < self.kl_target / ADAPTIVE_STEP:
            strength *= ADAPTIVE_STEP
        low, high = self.bounds
        self.current = min(max(1.0 + strength, low), high)

    def state_dict(self) -> dict:
        return {"current": self.current}

    def load_state_dict(self, state: dict | None) -> None:
        if state is not None:
            self.current = float(state["current"])


def schedule_error(args) -> str | None:
    """The rules of the guidance flags, one line, or None."""
    linear, adaptive = args.guidance_schedule == "linear", args.guidance_schedule == "adaptive"
    if linear != (args.guidance_final is not None):
        return "--guidance-final goes with --guidance-schedule linear (and linear needs it)"
    if linear and args.guidance_final == args.guidance:
        return "--guidance-schedule linear needs a --guidance-final other than --guidance (else: constant)"
    if adaptive != (args.guidance_kl_target is not None):
        return "--guidance-kl-target goes with --guidance-schedule adaptive (and adaptive needs it)"
    low, high = args.guidance_bounds
    if not adaptive and (low, high) != GuidanceArgs.guidance_bounds:
        return "--guidance-bounds goes with --guidance-schedule adaptive"
    if adaptive and not (1.0 <= low <= args.guidance <= high and args.guidance > 1.0):
        return (f"--guidance-schedule adaptive needs 1 <= low <= --guidance <= high and --guidance > 1 (the rule "
                f"scales γ - 1), got bounds ({low:g}, {high:g}) and --guidance {args.guidance:g}")  # fmt: skip
    return None
