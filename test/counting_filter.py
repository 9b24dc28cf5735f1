"""A safety filter wrapper that counts its QP solves: "never filtered" made checkable."""

from __future__ import annotations

from typing import Any


class CountingFilter:
    """Wraps a SafetyFilter and counts solve calls."""

    def __init__(self, core: Any) -> None:
        self.core = core
        self.calls = 0

    def solve(self, state: Any, u_nom: Any) -> Any:
        self.calls += 1
        return self.core.solve(state, u_nom)

    def __getattr__(self, name: str) -> Any:
        return getattr(self.core, name)
