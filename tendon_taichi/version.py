"""The package version (keep equal to ``pyproject.toml``)."""

__version__ = "0.1.0"
