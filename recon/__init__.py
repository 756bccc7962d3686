"""Registration of strike logs, surface reconstruction and the experiments that compare methods.

The folders follow the pipeline: ``registration/`` (strikes into the body frame), ``surfaces/``
(reconstruction methods, normals, one method run safely), ``experiments/`` (compare, stability,
the automatic choice, sweeps, charts, reports, the paper's studies). ``recon.api`` is the public
API in one screen; its verbs are also importable from here (``from recon import simulate``), loaded
on first use so that importing a subpackage stays light.
"""

_API = ("simulate", "ingest", "reconstruct", "score", "compare", "edges")
__all__ = list(_API)


def __getattr__(name: str):
    if name in _API:
        from recon import api

        return getattr(api, name)
    raise AttributeError(f"module 'recon' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted({*globals(), *_API})
