"""The typed settings registered as Hydra structured configs: the config files hold overrides only.

Each settings dataclass of the core is the one source of its defaults. Hydra composes it as the
schema of its node (``schema/<name>`` in a defaults list), so ``python diagnose.py
diagnosis.max_effects=two`` fails on the type before any work, a misspelled key fails by name,
and ``--cfg job`` still shows every value. Keys a task reads beside a core dataclass (the
refinement's method and starts, the generalisation's records) are declared here, once.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from hydra.core.config_store import ConfigStore

from pidyn.discrepancy.settings import DiagnosisSettings
from pidyn.models.predict_settings import PredictSettings
from pidyn.models.schedule import Schedule
from pidyn.refine.settings import RefineSettings


@dataclass
class RefineNode(RefineSettings):
    """``model.refine``: the refinement's settings and what the task layer reads beside them."""

    method: str = "multiple_shooting"  # multiple_shooting | none
    #: the starts scored beside PIDynNet's (when run; a peer's order-2 model when it maps onto the
    #: system); null: the data's start and every classical estimate (``runs.methods.default_starts``)
    starts: list[str] | None = None
    #: also refine from the same start with these segment states (e.g. [integrated]) and report it
    compare_states: list[str] = field(default_factory=list)


@dataclass
class GeneralizationNode(PredictSettings):
    """``generalization`` (``generalize.py``, the paper's Figures 4-5): how each unseen response is
    solved, and which responses are predicted."""

    duration: float = 20.0  # length of each predicted response (s)
    #: the identification record scaled and its time stretched
    own_scales: list[float] = field(default_factory=lambda: [0.5, 1.0, 1.5, 2.0])
    own_stretches: list[float] = field(default_factory=lambda: [0.8, 1.0, 1.25])
    #: the other shipped records, each at these multiples of the identification record's PGA
    other_records: list[str] = field(
        default_factory=lambda: [
            "kobe",
            "kobe_090",
            "el_centro",
            "el_centro_peer2000",
            "el_centro_peknold",
            "taft",
            "san_fernando",
            "tabas",
            "loma_prieta",
            "landers",
            "northridge",
            "kocaeli",
            "chichi",
        ]
    )
    other_scales: list[float] = field(default_factory=lambda: [0.5, 1.0])
    #: scale other records to the identification record's PGA (over the predicted segment)
    match_pga: bool = True
    align: bool = True  # start other records `lead` s before their strong motion (5 % Arias intensity)
    lead: float = 2.0
    max_cases: int | None = None


#: (name under ``schema/``, dataclass): what the config files name in their defaults lists
SCHEMAS = {
    "diagnosis": DiagnosisSettings,
    "schedule": Schedule,
    "refine": RefineNode,
    "generalization": GeneralizationNode,
}


def register() -> None:
    """Every schema into Hydra's config store (idempotent: a second call replaces the same nodes)."""
    store = ConfigStore.instance()
    for name, node in SCHEMAS.items():
        store.store(group="schema", name=name, node=node)
