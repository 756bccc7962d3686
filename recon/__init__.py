"""Registration of strike logs, surface reconstruction and the experiments that compare methods.

The folders follow the pipeline: ``registration/`` (strikes into the body frame), ``surfaces/``
(reconstruction methods, normals, one method run safely, the automatic choice and the truth-free
judgement), ``experiments/`` (compare, stability, sweeps, charts, reports, the paper's studies).
``recon.api`` is the public API; its verbs are also importable from here (``from recon import
simulate``) and listed by ``dir(recon)``, loaded on first use so that importing a subpackage (or
starting ``recon --help``) stays light.
"""

# The verbs of recon.api (its __all__ without the result classes; a test keeps them equal).
VERBS = ("check_scheduler", "check_seed", "compare", "default_truth", "demo", "edges",
         "export_altimetry", "follow", "ingest", "ingest_altimetry", "ingest_file",
         "is_altimetry", "is_kernel", "load", "method_cost", "method_listing", "presets",
         "reconstruct", "reconstruct_file", "refine", "report", "save", "scene_keys", "score",
         "simulate", "stability", "studies", "study", "study_all", "trajectory", "truth_of")
__all__ = list(VERBS)


def __getattr__(name: str):
    if name in VERBS:
        from recon import api

        return getattr(api, name)
    raise AttributeError(f"module 'recon' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted({*globals(), *VERBS})
