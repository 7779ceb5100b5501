"""The installed fieldcal version (one place; the package root and results read it)."""

__version__ = "0.2.0"
