"""
Fig. 6: three harmonic units against coupling, for several a
============================================================

Exact, eta against k relative to each a's threshold k_di(a).
"""

# %%
# Every point is exact, so the whole scene runs here, in a fraction of a second:
import tempfile

from fpe_harvester import run_scene

result = run_scene("fig6_eta_vs_k_several_a", tempfile.mkdtemp(), progress=False)
print(f"{len(result.rows)} points in {result.elapsed:.2f} s")

# %%
# The first rows of the table behind the figure:
print("\n".join(result.table().splitlines()[:12]))
