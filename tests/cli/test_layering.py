"""cli/ is a thin shell over ``recon.api``: it imports no other module of recon (or sim), at the
top of a file or inside a function."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

CLI = Path(__file__).resolve().parents[2] / "cli"
# Packages whose modules the CLI reaches only through recon.api.
BEHIND_THE_API = ("recon", "sim")


def forbidden_imports(source: str) -> list[str]:
    """The imports of ``source`` (anywhere in it) that reach recon or sim other than through
    ``recon.api``, as ``line: module`` strings."""
    found = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            modules = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            # ``from recon import api`` imports recon.api; ``from recon import x`` anything else
            modules = ([f"{node.module}.{alias.name}" for alias in node.names]
                       if node.module == "recon" else [node.module])
        else:
            continue
        for module in modules:
            top = module.split(".")[0]
            if top in BEHIND_THE_API and module != "recon.api":
                found.append(f"{node.lineno}: {module}")
    return found


@pytest.mark.parametrize("path", sorted(CLI.glob("*.py")), ids=lambda p: p.name)
def test_cli_imports_recon_only_through_its_api(path):
    assert forbidden_imports(path.read_text()) == []


def test_the_check_finds_imports_anywhere():
    source = ("import recon\n"
              "from recon import api, demo\n"
              "def run():\n"
              "    from recon.surfaces import methods\n"
              "    import sim.defaults\n"
              "    from recon.api import score\n"
              "    from formats import StrikeLog\n")
    assert forbidden_imports(source) == ["1: recon", "2: recon.demo", "4: recon.surfaces",
                                         "5: sim.defaults"]
