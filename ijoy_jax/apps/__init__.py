"""Command-line tools on top of the library: the ``ijoy`` command, the demo and every benchmark.

Nothing in the library imports this package."""
