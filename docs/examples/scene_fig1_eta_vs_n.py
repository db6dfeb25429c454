"""
Fig. 1: efficiency and Vrms of one unit against the exponent n
==============================================================

One oscillator in U(x) = a|x|^n for three strengths a. n = 2 is exact; every other n is
solved by Fokker-Planck, except at the strong kink (n = 1 and 1.25 at a = 2), where Monte Carlo
answers: where Fokker-Planck declines at once, or misses the scene's accuracy and is tried
again; the row's message says which. The paper's best point,
n = 1 and a = 0.5 with a printed eta = 0.609, is marked: two solvers give 0.6103, a
disagreement with the paper, not with each other.
"""

# %%
# The points were computed once, by
# ``harvester scene run fig1_eta_vs_n --out docs/_cache/fig1_eta_vs_n``. The run below finds every
# point in its copy of that cache, so it only writes the table and draws the figure.
import shutil
import tempfile
from pathlib import Path

from fpe_harvester import run_scene

cache = Path("../_cache/fig1_eta_vs_n/points.jsonl")  # the gallery runs this file in its folder
out = Path(tempfile.mkdtemp())
shutil.copy(cache, out)
result = run_scene("fig1_eta_vs_n", out, progress=False)
print(f"{result.reused} points from the cache, {result.computed} computed")

# %%
# The numbers behind the figure, each with its error, status and solver:
print(result.table())
