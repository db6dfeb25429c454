"""
Fig. 4: three harmonic units against coupling
=============================================

a = 0.5, N = 3, exact. eta grows toward the diffusive-instability threshold k_di = -1/3 and
stays finite there (status marginal); beyond it the ring has no stationary state.
"""

# %%
# Every point is exact, so the whole scene runs here, in a fraction of a second:
import tempfile

from fpe_harvester import run_scene

result = run_scene("fig4_eta_vs_k_harmonic", tempfile.mkdtemp(), progress=False)
print(f"{len(result.rows)} points in {result.elapsed:.2f} s")

# %%
# The first rows of the table behind the figure:
print("\n".join(result.table().splitlines()[:12]))
