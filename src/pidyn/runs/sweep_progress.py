"""A multirun's progress: each job that ends logs the sweep as k of n jobs with the time left at the
sweep's pace so far, whatever launcher ran it (the jobs of a joblib or a cluster launcher run in
other processes, so the count is kept in the sweep's folder, one line per job that ended).

Registered for every task as a Hydra callback (``conf/hydra/default.yaml``)."""

from __future__ import annotations

import json
import logging
import math
import time
from pathlib import Path
from typing import Any

from hydra.core.hydra_config import HydraConfig
from hydra.core.override_parser.overrides_parser import OverridesParser
from hydra.experimental.callback import Callback
from hydra.types import RunMode
from omegaconf import DictConfig

from pidyn.progress import time_left

log = logging.getLogger("pidyn.progress")

STATE = "sweep_progress.json"  # the sweep's size and start, written before any job
ENDED = "sweep_progress.log"  # one line per job that ended


def sweep_size(overrides: list[str]) -> int | None:
    """How many jobs the basic sweeper makes of ``overrides`` (the product of every key's choices,
    the last override of a key replacing the config's sweep of it, as the sweeper does); None
    where a sweep cannot be counted in advance (an interval of another sweeper)."""
    try:
        parsed = OverridesParser.create().parse_overrides(overrides)
        choices = {
            o.get_key_element(): len(list(o.sweep_string_iterator())) if o.is_sweep_override() else 1
            for o in parsed
        }
        return math.prod(choices.values())
    except Exception:  # noqa: BLE001  (a sweep another sweeper reads: no count, no harm)
        return None


class SweepProgress(Callback):
    def on_multirun_start(self, config: DictConfig, **kwargs: Any) -> None:
        hc = config.hydra
        params = [f"{k}={v}" for k, v in (hc.sweeper.get("params") or {}).items()]
        n = sweep_size(params + list(hc.overrides.task))
        folder = Path(str(hc.sweep.dir))
        folder.mkdir(parents=True, exist_ok=True)
        (folder / STATE).write_text(json.dumps({"jobs": n, "start": time.time()}))
        (folder / ENDED).unlink(missing_ok=True)
        if n:
            log.info("sweep of %d jobs into %s", n, folder)

    def on_job_end(self, config: DictConfig, job_return: Any, **kwargs: Any) -> None:
        try:
            hc = HydraConfig.get()
        except ValueError:
            return
        folder = Path(str(hc.sweep.dir))
        if hc.mode != RunMode.MULTIRUN or not (folder / STATE).exists():
            return
        state = json.loads((folder / STATE).read_text())
        status = getattr(getattr(job_return, "status", None), "name", "")
        with (folder / ENDED).open("a") as fh:  # one short line: appends from several processes stay whole
            fh.write(f"{hc.job.num} {status}\n")
        done = len((folder / ENDED).read_text().splitlines())
        n = state.get("jobs")
        ran = time.time() - float(state["start"])
        pace = f", {time_left(ran / done * (n - done))} at the sweep's pace" if n and done < n else ""
        log.info(
            "sweep: %d of %s jobs ended (job %s %s%s)%s",
            done,
            n if n else "?",
            hc.job.num,
            hc.job.override_dirname or "",
            "" if status == "COMPLETED" else f", {status.lower() or 'ended'}",
            pace,
        )
