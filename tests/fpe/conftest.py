"""Fixtures of the Fokker--Planck tests."""

from __future__ import annotations

from collections.abc import Callable

import pytest

from fpe_harvester.fpe.schemes.x import discretize


@pytest.fixture
def break_levels_from(monkeypatch: pytest.MonkeyPatch) -> Callable[[int], None]:
    """``break_levels_from(M)``: every level of degree >= M raises FloatingPointError
    ("simulated breakdown") inside the refinement."""

    def install(M_fail: int) -> None:
        real = discretize.solve_level

        def flaky(h, M, mesh, order, w):  # noqa: ANN001, ANN202
            if M >= M_fail:
                raise FloatingPointError("simulated breakdown")
            return real(h, M, mesh, order, w)

        monkeypatch.setattr(discretize, "solve_level", flaky)

    return install
