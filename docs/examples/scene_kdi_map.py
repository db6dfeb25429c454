"""
Beyond the paper: the threshold k_di(N, a) and the efficiency at it
===================================================================

Exact: the diffusive-instability threshold of harmonic rings of any size, and eta at the
threshold.
"""

# %%
# Every point is exact, so the whole scene runs here, in a fraction of a second:
import tempfile

from fpe_harvester import run_scene

result = run_scene("kdi_map", tempfile.mkdtemp(), progress=False)
print(f"{len(result.rows)} points in {result.elapsed:.2f} s")

# %%
# The first rows of the table behind the figure:
print("\n".join(result.table().splitlines()[:12]))
