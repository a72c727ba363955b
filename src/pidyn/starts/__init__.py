"""Where an identification starts: values read from the record itself (``data``), from an
earlier run or the config (``policy``), or from a peer's linear model (``peers``), and the
best of several by a free simulation (``score``). The train
task and the diagnosis ask here; nothing here knows either of them."""

from pidyn.starts.data import DataStart, start_from_data
from pidyn.starts.peers import peer_starts
from pidyn.starts.policy import start_from_run, start_policy, user_started, with_start
from pidyn.starts.score import cheapest

__all__ = [
    "DataStart",
    "cheapest",
    "peer_starts",
    "start_from_data",
    "start_from_run",
    "start_policy",
    "user_started",
    "with_start",
]
