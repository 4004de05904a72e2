"""Errors a user sees: a bad scene names the field path; a blow-up names step, body and quantity."""
from __future__ import annotations


class SceneError(ValueError):
    """Invalid scene input. `path` is the dotted field path, e.g. ``materials.aluminium.young``."""

    def __init__(self, path: str, message: str):
        self.path = path
        self.message = message
        super().__init__(f"{path}: {message}")


class BackendUnavailable(RuntimeError):
    """A reference code is not installed (a test or validation case turns this into a skip with the reason)."""


class UnsupportedFeature(SceneError):
    """A scene feature the chosen backend cannot express (never silently approximated)."""

    def __init__(self, backend: str, feature: str, why: str = ""):
        super().__init__(feature, f"not supported by backend '{backend}'" + (f": {why}" if why else ""))
        self.backend = backend


class SimulationError(RuntimeError):
    """A run that went wrong: NaN, energy jump, body leaving the domain. Names step, body and quantity."""

    def __init__(self, step: int, t: float, body: str, quantity: str, message: str):
        self.step, self.t, self.body, self.quantity = step, t, body, quantity
        super().__init__(f"step {step} (t={t:.6g} s), body {body}, {quantity}: {message}")


class ReferenceCodeError(RuntimeError):
    """A reference code (LIGGGHTS, YADE, Kratos) that crashed, ran past its timeout or wrote output that cannot be
    parsed: one line naming the code, what happened and the path of its log (the CLI prints it, exit code 6)."""

    def __init__(self, code: str, what: str, log):
        self.code, self.what, self.log = code, what, log
        super().__init__(f"{code} {what} (log: {log})")
