"""No function outside tests/ is more complex than radon's rank C (cyclomatic complexity 20).

The same check by hand: ``radon cc -s -n D formats sim metrics recon cli benchmarks`` prints
nothing.
"""

from __future__ import annotations

from pathlib import Path

from radon.complexity import cc_visit

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("formats", "sim", "metrics", "recon", "cli", "benchmarks")
# The upper bound of rank C.
MAX_COMPLEXITY = 20


def _blocks(path: Path):
    """Every function and method of one file (methods flattened out of their classes)."""
    for block in cc_visit(path.read_text(encoding="utf-8")):
        yield from getattr(block, "methods", ())
        yield block


def test_no_function_is_worse_than_rank_c():
    files = sorted(p for package in PACKAGES for p in (ROOT / package).rglob("*.py"))
    assert len(files) > 100   # the packages were found
    worse = [f"{path.relative_to(ROOT)}:{block.lineno} {block.fullname} ({block.complexity})"
             for path in files for block in _blocks(path)
             if block.complexity > MAX_COMPLEXITY]
    assert not worse, "split into smaller steps:\n" + "\n".join(worse)


def test_the_check_sees_a_complex_function(tmp_path):
    branches = "\n".join(f"    if x == {i}:\n        return {i}" for i in range(MAX_COMPLEXITY))
    source = f"def f(x):\n{branches}\n    return -1\n"
    (block,) = cc_visit(source)
    assert block.complexity == MAX_COMPLEXITY + 1
