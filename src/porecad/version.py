"""The porecad version (one place; ``porecad.__version__`` re-exports it)."""

__version__ = "0.2.0"
