"""The package version (one place: ``pyproject.toml`` reads it from here)."""

VERSION = "0.3.0"
