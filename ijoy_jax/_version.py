"""The package's version, ``project.version`` of pyproject.toml (``tests/test_cli.py`` holds them equal), which
the package root re-exports as ``ijoy_jax.__version__``: the name the rest of the package reads (the footstep
server's hello), once the root has imported."""

__version__ = "0.1.0"
