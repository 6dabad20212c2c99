"""FootCost: how well a terrain location serves as a foothold, plus the cost of the action.

Two paths compute the same costs: :mod:`~ijoy_jax.footcost.xla` (jnp, every named term; the default) and
:mod:`~ijoy_jax.footcost.pallas` (the totals as one fused kernel per decision, for GPUs). Both read the
per-terrain tables of :mod:`~ijoy_jax.footcost.index`, built once per terrain, and share the plane fit
(:mod:`~ijoy_jax.footcost.plane`), the rested sole (:mod:`~ijoy_jax.footcost.sole`) and the rules of what a
query may hold (:mod:`~ijoy_jax.footcost.query`).
"""

from ijoy_jax.footcost import index as index
from ijoy_jax.footcost import pallas as pallas
from ijoy_jax.footcost import plane as plane
from ijoy_jax.footcost import query as query
from ijoy_jax.footcost import sole as sole
from ijoy_jax.footcost import xla as xla
from ijoy_jax.footcost.index import TerrainIndex as TerrainIndex
from ijoy_jax.footcost.index import block_sums as block_sums
from ijoy_jax.footcost.index import index_terrain as index_terrain
from ijoy_jax.footcost.index import swing_corridor as swing_corridor
from ijoy_jax.footcost.pallas import foot_cost_fused as foot_cost_fused
from ijoy_jax.footcost.query import MAX_COORDINATE as MAX_COORDINATE
from ijoy_jax.footcost.query import query_supported as query_supported
from ijoy_jax.footcost.query import validate as validate
from ijoy_jax.footcost.xla import COST_TERMS as COST_TERMS
from ijoy_jax.footcost.xla import FootCostTerms as FootCostTerms
from ijoy_jax.footcost.xla import foot_cost as foot_cost
from ijoy_jax.footcost.xla import foot_cost_terms as foot_cost_terms
from ijoy_jax.limits import window_cells as window_cells

__all__ = [
    "COST_TERMS",
    "MAX_COORDINATE",
    "FootCostTerms",
    "TerrainIndex",
    "block_sums",
    "foot_cost",
    "foot_cost_fused",
    "foot_cost_terms",
    "index",
    "index_terrain",
    "pallas",
    "query_supported",
    "swing_corridor",
    "validate",
    "window_cells",
    "xla",
]
