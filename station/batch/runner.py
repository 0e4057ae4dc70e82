"""A batch: every item submitted to the Dask cluster at once, results taken as they finish (in
any order), each recorded in the state file and handed to ``on_result`` in this process (the
CLI's progress bar, its line per failed capture, the filing into the store)."""
from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Callable

from station.batch.inputs import Item
from station.batch.state import State, item_key, options_key
from station.batch.tasks import FAILED, Job, Outcome, run


@dataclass
class Summary:
    outcomes: list = field(default_factory=list)
    wall_s: float = 0.0
    workers: int = 0

    def count(self, status: str) -> int:
        return sum(o.status == status for o in self.outcomes)

    @property
    def poor_fits(self) -> int:
        """Fits that fail or did not converge: computed now, or skipped as done by an earlier
        batch (a batch resumed says them again: its exit status is 3 as the first one's was)."""
        return sum(o.status == "poor fit" or (o.status == "skipped" and o.verdict in ("fails", "not converged"))
                   for o in self.outcomes)

    @property
    def computed(self) -> list:
        return [o for o in self.outcomes if o.status != "skipped"]


def run_batch(client, command: str, items: list[Item], options: dict, state: State,
              on_result: Callable[[Outcome], None] | None = None) -> Summary:
    """Run ``command`` on every item on ``client`` (a distributed.Client); returns the outcomes
    in the items' order.  Interrupted (KeyboardInterrupt), the futures not finished are
    cancelled; what finished is in the state file."""
    from distributed import as_completed

    from station.batch.cluster import worker_count

    key_of_options = options_key(command, options)
    summary = Summary(workers=worker_count(client))
    started = time.perf_counter()
    jobs, keys = [], []
    for item in items:
        key = item_key(key_of_options, item.source, item.output)
        keys.append(key)
        jobs.append(Job(command, item.source, item.output, options, item.calibrations, state.previous(key)))
    stamp = time.time_ns()
    futures = client.map(run, jobs, key=[f"station-batch-{command}-{key_of_options}-{stamp}-{i}"
                                         for i in range(len(jobs))], pure=False, retries=0)
    index = {f.key: i for i, f in enumerate(futures)}
    results: list = [None] * len(items)
    try:
        # results fetched in groups as they finish (not one round trip each)
        for fut, value in as_completed(futures, with_results=True, raise_errors=False):
            i = index[fut.key]
            if isinstance(value, Outcome):
                outcome = value
            else:                              # the worker died with it (KilledWorker) or was lost
                outcome = Outcome(items[i].source, FAILED,
                                  f"the worker running it was lost ({type(value).__name__}: "
                                  f"{' '.join(str(value).split())[:160]})")
            results[i] = outcome
            state.record(keys[i], outcome)
            if on_result is not None:
                on_result(outcome)
            fut.release()
    finally:
        pending = [f for f in futures if not f.done()]
        if pending:
            client.cancel(pending)
    summary.outcomes = [r for r in results if r is not None]
    summary.wall_s = time.perf_counter() - started
    return summary
