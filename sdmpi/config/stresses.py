"""The registry of particle-stress contributions: one entry per sampled stress, used by the
sample stream (`sdmpi.dynamics.realisation.sample_fields`), the store (its datasets and
their attributes), the reducer (the rows of moduli.csv and viscosity.csv, between the
medium and the total) and the manual (docs/store.md, docs/reduce.md).

A new contribution is added here, sampled by the realisation, and reduced with no other
change. Run files written before a contribution existed lack its dataset; the reducer reads
it as zero where ``absent_is_zero`` says that is what it was (e.g. no collision stress was
recorded, the overlap correction's stress was simply not sampled), and says so.
"""

from dataclasses import dataclass


@dataclass(frozen=True)
class StressContribution:
    """component: its row in the reduced tables; dataset: its sample dataset (a 6-vector
    xx yy zz xy xz yz per step, in the job's stress unit); description: what it is."""

    component: str
    dataset: str
    description: str
    absent_is_zero: bool = False


#: the sampled contributions in table order; the hydrodynamic one comes first (a Maxwell
#: medium filters it: dataset + "_maxwell")
CONTRIBUTIONS = (
    StressContribution("hydrodynamic", "stress_hydrodynamic", "(1/V) sum S_H, viscous medium"),
    StressContribution("brownian", "stress_brownian", "-(kT/V) sum div(R_SU R_FU^-1)"),
    StressContribution("interparticle", "stress_interparticle",
                       "-(1/V) sum (x F_P + R_SU R_FU^-1 F_P)"),
    StressContribution("collision", "stress_collision",
                       "-(1/V) sum (r f e + R_SU R_FU^-1 F_C): the hard-sphere collisions implied "
                       "by the overlap correction", absent_is_zero=True),
)
