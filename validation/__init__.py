"""Validation: cases (scene + metrics + tolerances) -> metric rows -> report."""
