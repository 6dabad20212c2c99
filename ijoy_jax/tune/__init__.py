"""Tuning by gradient: a smooth relaxation of step selection (:mod:`.relax`) and tuners (:mod:`.inverse`)."""

from ijoy_jax.tune import inverse as inverse
from ijoy_jax.tune import relax as relax

__all__ = ["inverse", "relax"]
