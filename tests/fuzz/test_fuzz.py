"""The reduced fuzz run of CI: a few tens of seeded cases through `recon`.

The first kinds (damaged logs and files, scenes, arguments, special paths) run in-process; every
hostile kind (tests/fuzz/hostile.py) runs through a real process, traced where strace is
installed, as ``benchmarks/fuzz.py`` runs them all (a thousand or more cases, hangs timed).
"""

from __future__ import annotations

import pytest

from cli.main import main
from tests.fuzz.fuzzing import FIRST_KINDS, HOSTILE_KINDS, judge, make_case, make_inputs
from tests.fuzz.runner import can_drop_privileges, run_case, servers

# Seeds 0..N-1 of the first kinds, in-process: the same cases each run. Each takes about a
# second.
N_CASES = 30
# Seeds per hostile kind, each a real process of a few seconds.
N_HOSTILE = 3
# Hang limit of a hostile case's process: each finishes in seconds on these small inputs.
HANG_LIMIT_S = 240


@pytest.fixture(scope="module")
def inputs(tmp_path_factory):
    with servers() as addresses:
        yield make_inputs(tmp_path_factory.mktemp("fuzz-inputs")) | {"servers": addresses}


@pytest.mark.parametrize("seed", range(N_CASES))
def test_fuzz_case_fails_cleanly_or_succeeds_rightly(seed, inputs, tmp_path, capsys):
    kinds = sorted(set(FIRST_KINDS))
    case = make_case(seed, inputs, tmp_path, kinds[seed % len(kinds)])
    try:
        status = main(case.args)
    except SystemExit as exc:   # argparse's usage errors
        status = exc.code
    err = capsys.readouterr().err
    outcome = judge(case, status, err, secrets=inputs["secrets"])
    assert outcome in ("clean", "ok"), f"{case.name}: {outcome}: {case.args}\n{err}"


@pytest.mark.parametrize("kind", sorted(set(HOSTILE_KINDS)))
@pytest.mark.parametrize("seed", range(N_HOSTILE))
def test_hostile_case_fails_cleanly_or_succeeds_rightly(kind, seed, inputs, tmp_path):
    case = make_case(seed, inputs, tmp_path / "case", kind)
    if case.user is not None and not can_drop_privileges():
        pytest.skip("runs as an unprivileged user: needs root and setpriv")
    status, err, opened = run_case(case, tmp_path / "case", limit=HANG_LIMIT_S)
    outcome = judge(case, status, err, opened=opened, secrets=inputs["secrets"])
    assert outcome in ("clean", "ok"), f"{case.name}: {outcome}: {case.args}\n{err}"
