"""Coupling schemes: one module each, one registry line each."""
from __future__ import annotations

SCHEMES = ("gauss_seidel_weak",)
PREDICTORS = ("constant", "linear")   # gauss_seidel_weak.PREDICTORS (kept here: no import of the scheme)


def make_scheme(name: str):
    if name == "gauss_seidel_weak":
        from coupler.coupling.schemes.gauss_seidel_weak import GaussSeidelWeak
        return GaussSeidelWeak
    raise KeyError(name)
