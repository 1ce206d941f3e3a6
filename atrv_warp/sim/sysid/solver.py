"""Levenberg-Marquardt over the replays' residuals, from several starts at once in the unit box of the parameters'
bounds, and the fitted values' sandwich standard errors."""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from atrv_warp.sim.sysid.config import CalibrationConfig
from atrv_warp.sim.sysid.replay import Replay

__all__ = ["Start", "cauchy", "levenberg_marquardt", "sandwich_error"]


@dataclass
class Start:
    """One start's Levenberg–Marquardt state, in the unit box of the parameters' bounds."""

    unit: np.ndarray  # (P,) the current point, 0..1 of each parameter's range
    residuals: np.ndarray  # (S, R) at it
    jacobian: np.ndarray  # (S, R, P) d residuals / d unit, by forward differences
    damping: float
    robust: float | None
    """:attr:`CalibrationConfig.robust`."""
    evaluations: int = 1
    settled: float = math.inf
    """The undamped Gauss–Newton step from the current point: its largest move as a fraction of a range."""
    history: list = field(default_factory=list)

    @property
    def loss(self) -> float:
        """The mean of the segments' losses."""
        return float((self.residuals**2).sum() / len(self.residuals))

    @property
    def objective(self) -> float:
        """What the fit lowers: the mean of the segments' losses, each through :func:`cauchy`."""
        return float(cauchy((self.residuals**2).sum(-1), self.robust).mean())

    def weights(self) -> np.ndarray:
        """(S,) each segment's weight in the Gauss-Newton step (the derivative of :func:`cauchy` at its loss)."""
        loss = (self.residuals**2).sum(-1)
        return np.ones_like(loss) if self.robust is None else 1.0 / (1.0 + loss / self.robust)

    def step(self, damping: float) -> np.ndarray:
        """The Levenberg-Marquardt step from :attr:`unit` with Marquardt's scaling (a ``damping`` share of the normal
        equations' diagonal; 0: Gauss-Newton's), each segment weighted by :meth:`weights`, in the box: a parameter on
        a bound that the step would push out stays there, and the others are solved for without it."""
        w = self.weights()
        a = np.einsum("s,srp,srq->pq", w, self.jacobian, self.jacobian)
        g = np.einsum("s,srp,sr->p", w, self.jacobian, self.residuals)
        a = a + damping * np.diag(np.diag(a).clip(min=1e-12))
        free = np.ones(len(g), dtype=bool)
        for _ in range(len(g)):
            delta = np.zeros(len(g))
            delta[free] = -np.linalg.lstsq(a[np.ix_(free, free)], g[free], rcond=None)[0]
            out = free & (((self.unit <= 0.0) & (delta < 0)) | ((self.unit >= 1.0) & (delta > 0)))
            if not out.any():
                break
            free &= ~out
        return (self.unit + delta).clip(0.0, 1.0)


def cauchy(loss: np.ndarray, scale: float | None) -> np.ndarray:
    """Segment losses through Cauchy's ``scale * log(1 + loss / scale)``: as they are where small, growing only
    logarithmically past ``scale`` (``None``: as they are)."""
    return loss if scale is None else scale * np.log1p(loss / scale)


def levenberg_marquardt(replay: Replay, train: np.ndarray, names: list[str], low: np.ndarray, span: np.ndarray,
                         units: np.ndarray, cfg: CalibrationConfig, say: Callable[[str], None]) -> list[Start]:
    """Fit every start in ``units`` (K, P) at once: each iteration replays, for every start still moving, its
    trial point and a forward-difference step along each parameter from it, all in one batch of worlds. A trial that
    lowers the loss is taken, with its Jacobian; one that does not raises the damping and the old Jacobian serves
    again. A start stops once its undamped Gauss–Newton step moves no parameter more than ``cfg.tolerance`` of
    its range: a stationary point of the whole loss, valley or not."""
    count, p, t0 = len(train), len(names), time.perf_counter()

    def replay_points(points: list[np.ndarray]) -> list[tuple[np.ndarray, np.ndarray]]:
        """Residuals and Jacobian at each point: it and its P forward-difference neighbours, every training segment."""
        stencils, steps = [], []
        for u in points:
            h = np.where(u + cfg.difference_step <= 1.0, cfg.difference_step, -cfg.difference_step)  # inward
            stencils.append(np.concatenate([u[None], u[None] + np.diag(h)]))
            steps.append(h)
        grid = low + span * np.concatenate(stencils)  # (K (P + 1), P) parameter values
        per_world = {name: np.repeat(grid[:, j], count) for j, name in enumerate(names)}
        res = replay.residuals(np.tile(train, len(grid)), per_world)[0].reshape(len(points), p + 1, count, -1)
        return [(r[0], ((r[1:] - r[:1]) / h[:, None, None]).transpose(1, 2, 0)) for r, h in zip(res, steps)]

    starts = [Start(u, r, jac, cfg.damping, cfg.robust) for u, (r, jac) in zip(units, replay_points(list(units)))]
    for s in starts:
        s.history.append(s.objective)
    for it in range(cfg.iterations):
        moving = [s for s in starts if s.settled > cfg.tolerance]
        for s in moving:  # the undamped step's size: settled once it is within the tolerance
            s.settled = float(np.abs(s.step(0.0) - s.unit).max())
        moving = [s for s in moving if s.settled > cfg.tolerance]
        if not moving:
            break
        trials = [s.step(s.damping) for s in moving]
        for s, u, (r, jac) in zip(moving, trials, replay_points(trials)):
            s.evaluations += 1
            if float(cauchy((r**2).sum(-1), cfg.robust).mean()) < s.objective:
                s.unit, s.residuals, s.jacobian, s.damping = u, r, jac, max(s.damping / 3.0, 1e-6)
            else:
                s.damping *= 4.0
            s.history.append(s.objective)
        say(f"  iteration {it + 1:2d}: " + "; ".join(
            f"loss {s.objective:.4f} " + " ".join(f"{n} {low[j] + span[j] * s.unit[j]:.4g}" for j, n in enumerate(names))
            for s in starts) + f"  ({time.perf_counter() - t0:.0f} s)")
    for s in starts:  # where the loop ran out, each start's last undamped step
        s.settled = float(np.abs(s.step(0.0) - s.unit).max())
    return starts


def sandwich_error(start: Start, names: list[str], span: np.ndarray) -> tuple[dict[str, float], np.ndarray]:
    """Sandwich standard errors at the fit: ``H^-1 (sum_i g_i g_i^T) H^-1`` with ``g_i`` the gradient of training
    segment i's loss and ``H`` the Gauss–Newton Hessian of their sum, both from the fit's last Jacobian (segments
    taken as independent), and the parameters' correlation matrix; nan where ``H`` is singular."""
    jac, res, w = start.jacobian, start.residuals, start.weights()  # (S, R, P), (S, R), (S,)
    g = 2.0 * np.einsum("s,srp,sr->sp", w, jac, res)
    hessian = 2.0 * np.einsum("s,srp,srq->pq", w, jac, jac)
    if not bool((np.linalg.eigvalsh(hessian) > 1e-12 * np.abs(hessian).max()).all()):
        return {p: math.nan for p in names}, np.full((len(names), len(names)), math.nan)
    inverse = np.linalg.inv(hessian)
    cov = inverse @ (g.T @ g) @ inverse
    sd = np.sqrt(np.clip(np.diag(cov), 1e-300, None))
    return {p: float(span[j] * sd[j]) for j, p in enumerate(names)}, cov / np.outer(sd, sd)
