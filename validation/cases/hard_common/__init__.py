"""Shared pieces of the hard (stability) cases, `validation/cases/hard_*` (issue #17)."""
