"""The library's version: one place, read by `dpc_mjx.__version__`, the exports' and checkpoints'
sidecars and pyproject.toml (`[tool.setuptools.dynamic]`)."""

__version__ = "0.1.0"
