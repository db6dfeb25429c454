"""
Fig. 6: three harmonic units against coupling, for several a
============================================================

Exact, eta against k relative to each a's threshold k_di(a).
"""

import tempfile

from fpe_harvester import run_scene

result = run_scene("fig6_eta_vs_k_several_a", tempfile.mkdtemp(), progress=False)
print(f"{len(result.rows)} points, exact, in {result.elapsed:.2f} s")
