"""A differentiable Poisson solve for PyTorch, around mfm's cached factors.

``poisson_solve(solver, rhs)`` returns ``x = A^-1 rhs`` for the matrix ``A``
that ``solver`` (an ``mfm.PoissonSolver`` or ``mfm.ScreenedSolver``) has
factored, and back-propagates through it: ``A`` is symmetric, so the
gradient with respect to ``rhs`` is the same solve applied to the incoming
gradient. It stands in for the cached cholespy solver (``CholeskySolverF``
on ``L + eps I``) of the authors' training code::

    >>> import torch, mfm
    >>> from mfm.torch import poisson_solve
    >>> V, F = mfm.read_mesh("builtin:icosphere:2")
    >>> solver = mfm.PoissonSolver(V, F, eps=1e-6)
    >>> rhs = torch.randn(V.shape[0], 4, requires_grad=True)
    >>> x = poisson_solve(solver, rhs)
    >>> x.sum().backward()

``rhs`` is ``[n]`` or ``[n, K]`` (float32 or float64, any device); the
solve runs on the CPU and the result comes back on ``rhs``'s device and in
its dtype. This module imports torch; ``import mfm`` alone does not.
"""

import numpy as np
import torch

__all__ = ["poisson_solve"]


def _solve(solver, t):
    """``solver.solve`` of a tensor, as a tensor on the same device/dtype."""
    array = np.ascontiguousarray(t.detach().cpu().numpy())
    return torch.from_numpy(solver.solve(array)).to(device=t.device, dtype=t.dtype)


class _PoissonSolve(torch.autograd.Function):
    """``x = A^-1 b`` with ``dL/db = A^-1 dL/dx`` (``A`` symmetric)."""

    @staticmethod
    def forward(ctx, solver, rhs):
        ctx.solver = solver
        return _solve(solver, rhs)

    @staticmethod
    def backward(ctx, grad):
        return None, _solve(ctx.solver, grad)


def poisson_solve(solver, rhs):
    """Solves ``A x = rhs`` with the factor held by ``solver``, differentiably.

    ``solver``: an ``mfm.PoissonSolver`` (``A = L + eps I``) or
    ``mfm.ScreenedSolver`` (``A = L + tau M``). ``rhs``: a tensor ``[n]`` or
    ``[n, K]``, float32 or float64. Returns ``x`` with the shape, dtype and
    device of ``rhs``; its gradient with respect to ``rhs`` is the same solve.
    """
    if not isinstance(rhs, torch.Tensor):
        raise ValueError(f"rhs: expected a torch.Tensor, got {type(rhs).__name__}")
    if rhs.dtype not in (torch.float32, torch.float64):
        raise ValueError(f"rhs: expected float32 or float64, got {rhs.dtype}")
    return _PoissonSolve.apply(solver, rhs)
