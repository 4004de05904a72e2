"""2D plane-strain explicit material point method (issue #6)."""
