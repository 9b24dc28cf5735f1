"""Fixed-step explicit Runge–Kutta integrators defined by their Butcher tableaux.

An explicit s-stage method advances ``x' = f(t, x)`` by one step ``dt``:

    k_i     = f(t + c_i dt, x + dt * sum_{j<i} a_ij k_j),   i = 1..s
    x_{k+1} = x_k + dt * sum_i b_i k_i

Two methods are provided: ``ode3`` (Bogacki–Shampine, third order, the fixed-step solver
Matlab calls ``ode3`` and the one the paper's simulations used) and ``rk4`` (the classical
fourth-order method). Halving ``dt`` divides the global error by about ``2**order``.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

Derivative = Callable[[float, np.ndarray], np.ndarray]
"""Right-hand side ``f(t, x) -> x_dot`` over a flat state vector."""


@dataclass(frozen=True)
class ButcherTableau:
    """Coefficients of an explicit Runge–Kutta method.

    Attributes:
        name: Short name used in configuration files (``"ode3"``, ``"rk4"``).
        order: Order of accuracy p (global error O(dt**p)).
        a: Stage coefficients, shape (s, s), strictly lower triangular.
        b: Weights, shape (s,), summing to 1.
        c: Nodes, shape (s,), ``c_i = sum_j a_ij``.

    """

    name: str
    order: int
    a: np.ndarray
    b: np.ndarray
    c: np.ndarray

    def __post_init__(self) -> None:
        s = self.b.shape[0]
        if self.a.shape != (s, s) or self.c.shape != (s,):
            raise ValueError(
                f"ButcherTableau '{self.name}': expected a ({s}, {s}) and c ({s},), got "
                f'a {self.a.shape} and c {self.c.shape}'
            )
        if np.any(np.triu(self.a) != 0.0):
            raise ValueError(
                f"ButcherTableau '{self.name}': expected a strictly lower-triangular a "
                '(explicit method)'
            )
        if not np.isclose(self.b.sum(), 1.0) or not np.allclose(self.a.sum(axis=1), self.c):
            raise ValueError(
                f"ButcherTableau '{self.name}': expected sum(b) = 1 and c_i = sum_j a_ij, got "
                f'sum(b) = {self.b.sum()}, c = {self.c.tolist()}, row sums '
                f'{self.a.sum(axis=1).tolist()}'
            )
        for array in (self.a, self.b, self.c):
            array.setflags(write=False)

    @property
    def n_stages(self) -> int:
        """Number of stages s (right-hand-side evaluations per step)."""
        return self.b.shape[0]

    def step(
        self,
        f: Derivative,
        t: float,
        x: np.ndarray,
        dt: float,
        k1: np.ndarray | None = None,
    ) -> np.ndarray:
        """Advance ``x' = f(t, x)`` from ``(t, x)`` by one step ``dt``.

        Args:
            f: Right-hand side ``f(t, x) -> x_dot``, same shape as ``x``.
            t: Time at the start of the step, s.
            x: Flat state at ``t``, shape (N,).
            dt: Step, s (> 0).
            k1: ``f(t, x)`` if the caller has already evaluated it (it is the first stage of
                every explicit method); evaluated here otherwise.

        Returns:
            The state at ``t + dt``, shape (N,).

        """
        stages = np.empty((self.n_stages, x.shape[0]))
        stages[0] = f(t, x) if k1 is None else k1
        for i in range(1, self.n_stages):
            x_stage = x + dt * (self.a[i, :i] @ stages[:i])
            stages[i] = f(t + self.c[i] * dt, x_stage)
        return x + dt * (self.b @ stages)


ODE3 = ButcherTableau(
    name='ode3',
    order=3,
    a=np.array([[0.0, 0.0, 0.0], [1.0 / 2.0, 0.0, 0.0], [0.0, 3.0 / 4.0, 0.0]]),
    b=np.array([2.0 / 9.0, 1.0 / 3.0, 4.0 / 9.0]),
    c=np.array([0.0, 1.0 / 2.0, 3.0 / 4.0]),
)
"""Bogacki–Shampine 3(2) without its embedded error estimate: Matlab's fixed-step ode3."""

RK4 = ButcherTableau(
    name='rk4',
    order=4,
    a=np.array(
        [
            [0.0, 0.0, 0.0, 0.0],
            [1.0 / 2.0, 0.0, 0.0, 0.0],
            [0.0, 1.0 / 2.0, 0.0, 0.0],
            [0.0, 0.0, 1.0, 0.0],
        ]
    ),
    b=np.array([1.0 / 6.0, 1.0 / 3.0, 1.0 / 3.0, 1.0 / 6.0]),
    c=np.array([0.0, 1.0 / 2.0, 1.0 / 2.0, 1.0]),
)
"""The classical fourth-order Runge–Kutta method."""

INTEGRATORS: dict[str, ButcherTableau] = {tableau.name: tableau for tableau in (ODE3, RK4)}
"""Integrators by configuration name."""


def integrator(name: str) -> ButcherTableau:
    """Return the tableau called ``name`` (one of :data:`INTEGRATORS`); else ValueError."""
    try:
        return INTEGRATORS[name]
    except KeyError:
        raise ValueError(
            f'integrator: expected one of {sorted(INTEGRATORS)}, got {name!r}'
        ) from None
