"""
Fig. 5: optimal efficiency and Vrms against the number of harmonic units
========================================================================

a = 0.5, exact: for each ring size N the coupling that maximizes eta, which for a harmonic
ring is the marginal limit at the threshold k_di(N).
"""

# %%
# Every point is exact, so the whole scene runs here, in a fraction of a second:
import tempfile

from fpe_harvester import run_scene

result = run_scene("fig5_optimum_vs_N", tempfile.mkdtemp(), progress=False)
print(f"{len(result.rows)} points in {result.elapsed:.2f} s")

# %%
# The first rows of the table behind the figure:
print("\n".join(result.table().splitlines()[:12]))
