"""The package version (read by setup.cfg, logs, checkpoints and output markers)."""

__version__ = "0.3.0"
