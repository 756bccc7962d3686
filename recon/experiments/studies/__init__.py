"""The paper's studies, each one command: ``recon study NAME -o DIR [--quick] [--resume]``.

Every study is a module here exposing ``NAME``, ``TITLE`` and either

- ``cases(size) -> {key: run_case keyword arguments}`` (the module's own ``run_case`` if it
  has one) and ``finish(records, out_dir, size) ->
  {"claims", "files", "extra"}`` (the scene studies: ``recon.experiments.studies.runner``
  simulates, ingests
  and scores every case on Dask, then ``finish`` draws the charts and checks the paper's
  claims), or
- ``run(out_dir, *, size, scheduler, resume, n_workers) -> summary`` (``methods``, which runs
  ``recon.experiments.compare`` per condition, and ``pointing``, whose cases each reconstruct
  and score two clouds).

Every study writes ``DIR/summary.json`` (claims with our numbers and a verdict, files, failures,
score options), ``DIR/results.csv`` (one row per case and time prefix), ``DIR/results.jsonl``
(the raw records, what ``--resume`` reads) and its charts (PNG).

>>> from recon.experiments import studies
>>> studies.names()[:3]
['inclination', 'duration', 'slew']
"""

from __future__ import annotations

import importlib
import json
import time
from pathlib import Path
from types import ModuleType

from formats.atomic import write_text_atomically
from formats.errors import ParameterError
from formats.paths import writing_into
from recon.experiments.studies.runner import SIZES, check_size

# Study modules, in the order of the paper (and of ``recon study --list``).
STUDIES = ("inclination", "duration", "slew", "patterns", "rso", "errors", "methods",
           "closed-loop", "pointing")
# ``recon study all`` writes this beside the study directories.
INDEX_JSON = "index.json"

__all__ = ["SIZES", "STUDIES", "ParameterError", "describe", "get", "names", "run", "run_all"]


def names() -> list[str]:
    """The study names, in the paper's order."""
    return list(STUDIES)


def get(name: str) -> ModuleType:
    """The module of study ``name``.

    Raises
    ------
    ParameterError
        No such study; the message lists them.
    """
    if name not in STUDIES:
        raise ParameterError(f"unknown study {name!r} (studies: {', '.join(STUDIES)}, or all)")
    return importlib.import_module(f"recon.experiments.studies.{name.replace('-', '_')}")


def describe() -> list[tuple[str, str]]:
    """``(name, title)`` of every study."""
    return [(name, get(name).TITLE) for name in STUDIES]


def check_scheduler(scheduler: str | None, *, connect: bool = True) -> str | None:
    """Validate a ``--scheduler`` value; for an address, check that a scheduler answers there.

    Raises
    ------
    ParameterError
        Not ``threads``, ``serial`` or an address, or nothing answers at the address.
    """
    from recon.experiments.sweep import check_scheduler as check_address
    from recon.experiments.sweep import connect as connect_client
    from recon.experiments.sweep import quiet_dask

    if check_address(scheduler, ParameterError) in (None, "threads", "serial"):
        return scheduler
    if connect:
        client = connect_client(scheduler, ParameterError)
        with quiet_dask():
            client.close()
    return scheduler


def run(name: str, out_dir, *, size: str = "full", scheduler: str | None = None,
        resume: bool = False, n_workers: int | None = None, checked: bool = False) -> dict:
    """Run one study into ``out_dir``; return its summary (also in ``DIR/summary.json``).

    Parameters
    ----------
    name : str
        One of ``names()``.
    out_dir : str or Path
        Created if needed; removed again if the study fails before writing into it.
    size : {"full", "quick", "tiny"}
        ``full`` as in the paper, ``quick`` for CI, ``tiny`` for the tests.
    scheduler : str, optional
        Dask scheduler address, ``threads`` or ``serial`` (default: a local cluster);
        ``recon.experiments.sweep``.
    resume : bool
        Keep finished cases of an interrupted run (failed ones run again).
    n_workers : int, optional
        Cases at once on this machine (default: one per core): the worker processes of the
        local Dask cluster, or threads with ``"threads"``; not used by ``"serial"`` or on a
        cluster given by address.
    checked : bool
        The scheduler was already checked (``run_all``).
    """
    from recon.experiments.studies import runner

    module = get(name)
    check_size(size)
    if not checked:
        check_scheduler(scheduler)
    start = time.perf_counter()
    # Created here, and removed again (with the parents this made) when the study fails
    # before writing into it.
    with writing_into(out_dir, ParameterError) as out_dir:
        if hasattr(module, "run"):
            summary = module.run(out_dir, size=size, scheduler=scheduler, resume=resume,
                                 n_workers=n_workers)
        else:
            cases = module.cases(size)
            records = runner.execute(name, cases, out_dir, size=size, scheduler=scheduler,
                                     resume=resume, n_workers=n_workers,
                                     func=getattr(module, "run_case", runner.run_case))
            runner.write_csv(runner.rows(records), out_dir / runner.RESULTS_CSV)
            done = module.finish(runner.ok(records), out_dir, size)
            runner.write_summary(out_dir, study=name, title=module.TITLE, size=size,
                                 records=records, claims=done["claims"],
                                 files=[runner.RESULTS_CSV, *done["files"]],
                                 extra=done.get("extra"))
            summary = json.loads((out_dir / runner.SUMMARY_JSON).read_text())
        summary["wall_time_s"] = time.perf_counter() - start
        write_text_atomically(out_dir / runner.SUMMARY_JSON,
                              json.dumps(summary, indent=2) + "\n")
        return summary


def run_all(out_dir, *, size: str = "full", scheduler: str | None = None,
            resume: bool = False, n_workers: int | None = None,
            only: list[str] | None = None) -> dict:
    """Run every study (or ``only`` these) into ``out_dir/NAME/``; write ``out_dir/index.json``.

    Without a scheduler, one local Dask cluster serves all the studies (started once).

    Returns
    -------
    dict
        ``size``, ``studies`` (per study: ``wall_time_s``, ``n_cases``, ``n_failed``,
        ``verdicts``), ``wall_time_s``.
    """
    check_size(size)
    chosen = list(only) if only else names()
    for name in chosen:
        get(name)
    check_scheduler(scheduler)
    # Removed again, as each study's own directory is, when the first study fails before
    # writing.
    with writing_into(out_dir, ParameterError) as out_dir:
        return _run_all(out_dir, chosen, size=size, scheduler=scheduler, resume=resume,
                        n_workers=n_workers)


def _run_all(out_dir: Path, chosen: list[str], *, size: str, scheduler: str | None,
             resume: bool, n_workers: int | None) -> dict:
    """``run_all`` once its arguments are checked and ``out_dir`` exists."""
    from tqdm import tqdm

    start = time.perf_counter()
    index = {"size": size, "studies": {}, "wall_time_s": None}
    cluster = None
    # The overall bar, one step per study, above each study's own bar of its cases.
    overall = tqdm(total=len(chosen), desc="studies", unit="study", disable=None)
    try:
        if scheduler is None:
            from recon.experiments.sweep import default_workers, local_cluster

            cluster = local_cluster(n_workers or default_workers())
            address = cluster.scheduler_address
        else:
            address = scheduler
        for name in chosen:
            overall.set_postfix_str(name)
            summary = run(name, out_dir / name, size=size, scheduler=address, resume=resume,
                          n_workers=n_workers, checked=True)
            overall.update(1)
            verdicts = {}
            for c in summary.get("claims", []):
                verdicts[c["verdict"]] = verdicts.get(c["verdict"], 0) + 1
            index["studies"][name] = {"title": summary["title"],
                                      "wall_time_s": summary["wall_time_s"],
                                      "n_cases": summary["n_cases"],
                                      "n_failed": summary["n_failed"], "verdicts": verdicts}
            index["wall_time_s"] = time.perf_counter() - start
            write_text_atomically(out_dir / INDEX_JSON, json.dumps(index, indent=2) + "\n")
    finally:
        overall.close()
        if cluster is not None:
            cluster.close()
    index["wall_time_s"] = time.perf_counter() - start
    write_text_atomically(out_dir / INDEX_JSON, json.dumps(index, indent=2) + "\n")
    return index
