"""Fixtures of the surface tests."""

from __future__ import annotations

import pytest


@pytest.fixture
def fitted_labels(monkeypatch) -> list[str]:
    """The label of every isolated fit the test then makes, in the order they are handed out
    (``isolation.run_isolated`` wrapped)."""
    from recon.surfaces import isolation

    labels: list[str] = []
    fit = isolation.run_isolated

    def counted(run, *args, **kwargs):
        labels.append(run.label)
        return fit(run, *args, **kwargs)

    monkeypatch.setattr(isolation, "run_isolated", counted)
    return labels
