"""Notes with codes: a note is text for people ending in its code in brackets
(``... outside its range [ls_start_rejected]``), so that programs (tests, aggregators, a user's
script) match the code, not the wording, and the files stay plain text.

Every code is in one table (``CODES``) with what it means; the note itself says it for the case
at hand, with its numbers. A code not in the table is refused when the note is made."""

from __future__ import annotations

import re
from collections.abc import Iterable

_CODE = re.compile(r"\[([a-z][a-z0-9_]*)\]$")

#: every note code and what it means, by where it arises
CODES: dict[str, str] = {
    # reading a record
    "channel_missing": "a channel the station file names is not in this event; left out (data.on_missing=drop)",
    "cut_to_shortest": "channels of different lengths (two recorders): cut to the shortest",
    "resampled": "the record was resampled to the time step asked (polyphase, zero phase)",
    "outputs_unused": "measured outputs beyond the model's degrees of freedom are not used",
    "recorders_aligned": "a film record's recorders were put on one clock, read from the supports' ground motions",
    "recorders_not_aligned": "a film record's recorders could not be put on one clock: each keeps its own",
    "velocity_integrated": "a channel without a velocity block: its velocity integrated from its acceleration",
    "lag_not_trusted": "an IMU floor correlates too weakly with the table to trust its time lag; it is not used",
    # PIDynNet's windows
    "ls_start_rejected": "a least-squares start put a parameter outside its range or left it undetermined",
    "ls_start_determined": "a later window's least-squares start determined parameters earlier windows did not",
    "latent_start_undetermined": "the latent least-squares start does not determine the latent shape here",
    "on_clamp_bound": "a parameter ended a window on its 3-sigma clamp bound",
    # the refinement and its intervals
    "polished_from_rest": "a model from several records: the shooting estimate finished by output error from rest, as predictions simulate it",
    "starts_diverge": "no starting estimate simulates the record without blowing up",
    "start_not_preferred": "the preferred start simulates the record worse than another; the other was used",
    "pidynnet_behind": "a peer's estimate simulated the record far better than PIDynNet's, which stopped there (model.schedule.stop_behind)",
    "period_scan_moved": "a scan of the period found a lower basin of the cost than the local solve",
    "not_at_rest": "the record does not start at rest: its initial state is estimated",
    "near_singular": "the information matrix is near-singular: some combination of parameters is not determined",
    "poorly_determined": "a parameter's 95 % interval is too wide for the record to determine it",
    "not_separable": "parameters correlate so that the record cannot separate them",
    "supports_not_distinguished": "the records do not tell two supports' stiffnesses apart",
    "support_undetermined": "a support's stiffness interval spans more than the reporting limit",
    # what the run reports
    "model_diverges": "the identified model blows up when simulated over the record",
    "model_inadequate": "the identified model does not describe the record: its estimates are not properties",
    "model_rejected_by_its_records": "the model that predicts does not describe the records it was identified on (its run's adequacy test)",
    "beyond_training_amplitude": "a predicted record shakes the structure harder or more weakly than any record the model was identified on",
    "nonlinear_not_earned": "a model from several records: its nonlinear terms do not predict its own records better, each left out and predicted by the models refitted without it; the linear model of the same layout is used",
    "model_choice_undecided": "a model from several records: its own records, each left out, cannot tell its nonlinear model from the linear one (the mean log ratio of their errors within two standard errors of 0); the choice between them is a coin",
    "damping_not_a_property": "a mode's damping is the fit's, not reported as the structure's",
    "figure_failed": "a figure could not be drawn; the run's results stand",
    "not_applicable": "a baseline does not apply to this record or system",
    # the diagnosis
    "worse_than_trivial": "the nominal model predicts the held-out part worse than knowing nothing",
    "name_unearned": "the named effects' model predicts the held-out part no better: no name is kept",
    "not_decided": "the output-error check cannot tell the named effect from its rivals",
    "refused_undetermined": "a storey effect predicted better, but its size is not determined",
    "refused_no_heldout_gain": "a storey effect passed the screening but did not predict the held-out part better",
    "heldout_fails": "nothing named, but the nominal building fails the held-out test",
    "fit_fails": "nothing named, but the nominal building or deck does not fit its fitting part down to the noise",
    "deck_not_rigid": "the deck channels do not move as a deck rigid in plan: the deck itself bends or twists",
    "effect_support_not_distinguished": "the deck channels change alike for an effect at either of two supports",
}


def note(code: str, text: str) -> str:
    """``text`` tagged with ``code`` (lower case, digits and underscores)."""
    if code not in CODES:
        raise ValueError(f"note code '{code}' is not in pidyn.notes.CODES: add it there, with what it means")
    return f"{text} [{code}]"


def code_of(text: str) -> str | None:
    """The code a note ends with, or None for a note without one."""
    m = _CODE.search(text.rstrip())
    return m.group(1) if m else None


def codes(notes: Iterable[str] | str | None) -> set[str]:
    """The codes of a list of notes (or of one note)."""
    if notes is None:
        return set()
    if isinstance(notes, str):
        notes = [notes]
    return {c for n in notes if (c := code_of(n))}
