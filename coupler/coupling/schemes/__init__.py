"""Coupling schemes: one module each, one registry line each."""
from __future__ import annotations

from coupler.coupling.schemes.predictors import PREDICTORS  # noqa: F401  (the [coupling] predictor field)

SCHEMES = ("gauss_seidel_weak",)


def make_scheme(name: str):
    if name == "gauss_seidel_weak":
        from coupler.coupling.schemes.gauss_seidel_weak import GaussSeidelWeak
        return GaussSeidelWeak
    raise KeyError(name)
