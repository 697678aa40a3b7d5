"""The Ercuts integrator (Zhu, Xu, Pan 2010) and the paper's steps, one module each:

1. :mod:`.initialization` — rough BDPT image and its energy P; :mod:`.seeding` — seed paths
   from fresh BDPT samples (the BDPT integrator's ``on_connections`` callback);
2. :mod:`.er_sampling` — energy-redistribution Markov chains, with :mod:`.mutations` (Veach's
   perturbations and a bidirectional mutation) over the eye-first paths of :mod:`.paths`;
3. :mod:`.vpl` — a VPL at x2 of every chain state, merged and normalised;
4. :mod:`.light_tree` — the binary light tree with the paper's pairing weight;
5. :mod:`.lightcuts` — the cut per shading point; :mod:`.gather` runs it over the image.

:mod:`.integrator` drives the phases; :mod:`.progressive` repeats them as independent
iterations; :mod:`.pacing` holds their time shares, progress
fractions and the gather's pacing under a time limit.
"""
from .integrator import ErcutsIntegrator

__all__ = ["ErcutsIntegrator"]
