"""The package's version, ``project.version`` of pyproject.toml (``tests/test_cli.py`` holds them equal): in
a module of its own so that parts below the package root (the footstep server's hello) can name it without
importing the root."""

__version__ = "0.1.0"
