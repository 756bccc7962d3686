"""The reduced fuzz run of CI: a few tens of seeded cases through `recon` in-process (issue 13).

``benchmarks/fuzz.py`` runs the full form (hundreds of cases, real processes, hangs timed).
"""

from __future__ import annotations

import pytest

from cli.main import main
from tests.fuzz.fuzzing import make_case, make_inputs

# Seeds 0..N-1: the same cases each run. Each takes about a second.
N_CASES = 30


@pytest.fixture(scope="module")
def inputs(tmp_path_factory):
    return make_inputs(tmp_path_factory.mktemp("fuzz-inputs"))


@pytest.mark.parametrize("seed", range(N_CASES))
def test_fuzz_case_fails_cleanly_or_succeeds_rightly(seed, inputs, tmp_path, capsys):
    from tests.fuzz.fuzzing import judge

    case = make_case(seed, inputs, tmp_path)
    try:
        status = main(case.args)
    except SystemExit as exc:   # argparse's usage errors
        status = exc.code
    err = capsys.readouterr().err
    outcome = judge(case, status, err)
    assert outcome in ("clean", "ok"), f"{case.name}: {outcome}: {case.args}\n{err}"
