"""
Beyond the paper: the threshold k_di(N, a) and the efficiency at it
===================================================================

Exact: the diffusive-instability threshold of harmonic rings of any size, and eta at the
threshold.
"""

import tempfile

from fpe_harvester import run_scene

result = run_scene("kdi_map", tempfile.mkdtemp(), progress=False)
print(f"{len(result.rows)} points, exact, in {result.elapsed:.2f} s")
