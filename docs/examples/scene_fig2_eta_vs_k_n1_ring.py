"""
Fig. 2: a ring of three kink units against small negative coupling
==================================================================

U = 0.5|x|, N = 3, Monte Carlo. For n < 2 every k < 0 leaves the ring only metastable: paths
escape, and the points where they did are marked on the bottom edge (their averages are
over the time before escape). The paper prints eta = 0.62 at k = -0.01 and a divergence
near k = -0.02 in finite-time runs.
"""

# %%
# The points were computed once, by
# ``harvester scene run fig2_eta_vs_k_n1_ring --out docs/_cache/fig2_eta_vs_k_n1_ring``. The run below finds every
# point in its copy of that cache, so it only writes the table and draws the figure.
import shutil
import tempfile
from pathlib import Path

from fpe_harvester import run_scene

cache = Path("../_cache/fig2_eta_vs_k_n1_ring/points.jsonl")  # the gallery runs this file in its folder
out = Path(tempfile.mkdtemp())
shutil.copy(cache, out)
result = run_scene("fig2_eta_vs_k_n1_ring", out, progress=False)
print(f"{result.reused} points from the cache, {result.computed} computed")

# %%
# The numbers behind the figure, each with its error, status and solver:
print(result.table())
