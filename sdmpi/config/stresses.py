"""The registry of particle-stress contributions: one entry per sampled stress, used by the
sample stream (`sdmpi.dynamics.setup.sample_fields`), the store (its datasets and
their attributes), the reducer (the rows of moduli.csv and viscosity.csv, between the
medium and the total) and the manual (docs/store.md, docs/reduce.md).

A new contribution is added here, sampled by the realisation, and reduced with no other
change. A run file without a contribution's dataset is refused by the reducer, except
where ``absent_is_zero`` is set (the collision stress): that contribution is then reduced
as zero.

Sample time: sample k of every stream is stored at row k, t_k = k dt, and represents
t_k + ``sample_offset`` dt, at which the reducer projects it
(`sdmpi.analysis.projection.project_periods`, ``t0 = offset dt``); the store writes the
offset as the ``sample_offset`` attribute of each stress dataset, and files without it
take ``unrecorded_offset``. Offsets: hydrodynamic, Brownian and interparticle 0 (functions
of the configuration x_k); collision +1/2 (the impulses at the end of step k are that
step's mean collision force; -1/2 in files without the attribute, whose sample k is the
correction made at the start of step k). Why, and the error of another choice:
docs/physics.md, "Sample times".
"""

from dataclasses import dataclass


@dataclass(frozen=True)
class StressContribution:
    """component: its row in the reduced tables; dataset: its sample dataset (a 6-vector
    xx yy zz xy xz yz per step, in the job's stress unit); description: what it is;
    absent_is_zero: files without the dataset reduce it as zero; sample_offset: sample k
    represents t_k + sample_offset dt (module docstring); unrecorded_offset: that of files
    without the attribute (None: sample_offset)."""

    component: str
    dataset: str
    description: str
    absent_is_zero: bool = False
    sample_offset: float = 0.0
    unrecorded_offset: float | None = None


#: the sampled contributions in table order; the hydrodynamic one comes first (a Maxwell
#: medium filters it: dataset + "_maxwell")
CONTRIBUTIONS = (
    StressContribution("hydrodynamic", "stress_hydrodynamic", "(1/V) sum S_H, viscous medium"),
    StressContribution("brownian", "stress_brownian", "-(kT/V) sum div(R_SU R_FU^-1)"),
    StressContribution("interparticle", "stress_interparticle",
                       "-(1/V) sum (x F_P + R_SU R_FU^-1 F_P)"),
    StressContribution("collision", "stress_collision",
                       "-(1/V) sum (r f e + R_SU R_FU^-1 F_C): the hard-sphere collisions implied "
                       "by the overlap correction", absent_is_zero=True, sample_offset=0.5,
                       unrecorded_offset=-0.5),
)

def contribution_datasets(medium_kind: str) -> tuple[str, ...]:
    """The sample dataset of each contribution, in the order of `CONTRIBUTIONS`, for a
    medium of kind ``medium_kind`` (``medium.kind``): in a Maxwell medium the hydrodynamic
    stress filtered by its modes (``stress_hydrodynamic_maxwell``)."""
    datasets = tuple(c.dataset for c in CONTRIBUTIONS)
    if medium_kind == "maxwell":
        return (datasets[0] + "_maxwell",) + datasets[1:]
    return datasets


#: stress datasets that are parts or filtered forms of a contribution's, sampled with it
DERIVED = {"stress_hydrodynamic_maxwell": "stress_hydrodynamic",
           "stresslets": "stress_hydrodynamic",
           "stress_contact": "stress_interparticle"}


def _contribution(dataset):
    """The registry entry of a stress dataset or of the one it derives from (`DERIVED`);
    None for datasets that are not stresses."""
    dataset = DERIVED.get(dataset, dataset)
    return next((c for c in CONTRIBUTIONS if c.dataset == dataset), None)


def sample_offset(dataset):
    """The sample_offset (units of dt) of a stress dataset of the registry or derived from
    one (`DERIVED`); None for datasets that are not stresses."""
    c = _contribution(dataset)
    return None if c is None else c.sample_offset


def unrecorded_offset(dataset):
    """The sample offset of a stress dataset in files written without the attribute."""
    c = _contribution(dataset)
    return None if c is None else (c.sample_offset if c.unrecorded_offset is None else c.unrecorded_offset)
