"""The toolkit's version (one place: the façade, pyproject and run records read it here)."""

__version__ = "0.1.0"
