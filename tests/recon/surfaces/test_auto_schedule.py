"""``-m auto``'s schedule: the order its fits are handed out in, the next level fitted ahead, the
warm workers; none of it changes a candidate's figures or the choice."""

from __future__ import annotations

from sphere_clouds import small_sphere

from formats.geometry import Cloud
from recon.surfaces import auto, isolation
from recon.surfaces.auto import choose, format_choice

# planes (level 0, fitted on every fold) is far from a sphere, the ellipsoid mesh of level 1
# measurably better: the ladder goes on to level 2, where the planes at a wider threshold are
# outpaced on the first stage's fold and the ellipsoid is fitted on every fold.
LADDER = ((("planes", {}),), (("ellipsoid", {"subdivisions": 3}),),
          (("ellipsoid", {}), ("planes", {"threshold": 2.0})))


def figures(choice) -> dict:
    """Every candidate's outcome, without its fit time."""
    return {c.label: (c.status, c.chi2, c.chi2_se, c.holes, c.violated, c.n_faces, c.chosen)
            for c in choice.candidates}


def test_fits_are_handed_out_fold_by_fold_the_next_level_ahead_and_choose_alike(monkeypatch):
    """One worker runs the fits in the order they are handed out: fold by fold, the models
    fitted on every fold first, then on the first stage's fold the raced level; then the
    raced level fold by fold, each stage of the race after its fold, and then, before the
    ladder has decided to go on, the next level on the first stage's fold; the next level's
    own call fits only its other folds (the far planes none). The candidates
    and the choice are those of fitting each level when the ladder reaches it."""
    cloud, view = small_sphere()
    monkeypatch.setattr(auto, "LADDER", LADDER)
    monkeypatch.setattr(auto, "ALWAYS_LEVELS", 2)
    options = {"view_points": view, "uncertainty": cloud.attributes, "seed": 0, "n_workers": 1}
    fits, contexts = [], []
    fit, context = isolation.run_isolated, auto._context

    def counted(run, prepared, *args, **kwargs):
        fits.append((run.label, prepared))
        return fit(run, prepared, *args, **kwargs)

    def kept(*args, **kwargs):
        contexts.append(context(*args, **kwargs))
        return contexts[-1]

    monkeypatch.setattr(isolation, "run_isolated", counted)
    monkeypatch.setattr(auto, "_context", kept)
    ahead = choose(cloud.points, **options)
    folds = [f.prepared for f in contexts[-1].folds]
    order = [(label, next(f for f, p in enumerate(folds) if p is prepared))
             for label, prepared in fits]
    assert order == ([("planes", 0), ("ellipsoid subdivisions=3", 0)]
                     + [("planes", f) for f in range(1, 4)]
                     + [("ellipsoid subdivisions=3", f) for f in range(1, 4)]
                     + [("ellipsoid", 0), ("planes threshold=2", 0), ("ellipsoid", 1),
                        ("ellipsoid", 2), ("ellipsoid", 3)]), order
    table = {c.label: c for c in ahead.candidates}
    assert table["planes threshold=2"].status == "outpaced", format_choice(ahead)
    assert table["ellipsoid"].scored and ahead.label.startswith("ellipsoid")

    # the same ladder with each level fitted only when the ladder reaches it
    whole = auto._fit_and_judge

    def unahead(*args, ahead=None, given=None, **kwargs):
        return whole(*args, **kwargs)

    monkeypatch.setattr(auto, "_fit_and_judge", unahead)
    fits.clear()
    plain = choose(cloud.points, **options)
    assert len(fits) == 13 and plain.label == ahead.label
    assert figures(plain) == figures(ahead)


def test_the_next_level_is_handed_out_beside_a_stage_that_leaves_a_worker_idle(monkeypatch):
    """With two workers, a stage of the race waits for its last fit, or hands out one (the one
    raced run left in), while a worker is idle: the next level's fits ahead are handed out
    then, before the race's last folds, instead of after them. The choice is that of the
    single worker's order."""
    import concurrent.futures

    cloud, view = small_sphere()
    monkeypatch.setattr(auto, "LADDER", LADDER)
    monkeypatch.setattr(auto, "ALWAYS_LEVELS", 2)
    handed: list[tuple[str, int]] = []
    contexts = []
    context = auto._context

    def kept(*args, **kwargs):
        contexts.append(context(*args, **kwargs))
        return contexts[-1]

    class Recorded(concurrent.futures.ThreadPoolExecutor):
        def submit(self, fn, *args, **kwargs):
            if fn is auto._fit_fold:   # (fit, run, fold): not the folds' preparation
                run, fold = args[1:3]
                handed.append((run.label, next(f for f, known in enumerate(contexts[-1].folds)
                                               if known is fold)))
            return super().submit(fn, *args, **kwargs)

    monkeypatch.setattr(auto, "_context", kept)
    monkeypatch.setattr(concurrent.futures, "ThreadPoolExecutor", Recorded)
    options = {"view_points": view, "uncertainty": cloud.attributes, "seed": 0}
    two = choose(cloud.points, n_workers=2, **options)
    last = handed.index(("ellipsoid subdivisions=3", 2))
    assert handed.index(("ellipsoid", 0)) < last, handed
    assert handed.index(("planes threshold=2", 0)) < last, handed
    one = choose(cloud.points, n_workers=1, **options)
    assert figures(one) == figures(two)


def test_the_next_level_fitted_ahead_is_dropped_when_the_ladder_stops(monkeypatch,
                                                                      fitted_labels):
    """When the ladder stops, the next level's runs fitted ahead leave no candidate: they are
    skipped as without the fits ahead, and the choice is the same."""
    cloud, view = small_sphere()
    # the ellipsoid of level 0 is exact: the coarser mesh of level 1 is not measurably better
    monkeypatch.setattr(auto, "LADDER", ((("ellipsoid", {}),),
                                         (("ellipsoid", {"subdivisions": 3}),),
                                         (("planes", {}),)))
    monkeypatch.setattr(auto, "ALWAYS_LEVELS", 2)
    fits = fitted_labels
    choice = choose(cloud.points, view_points=view, uncertainty=cloud.attributes, seed=0)
    assert fits.count("planes") == 1   # fitted ahead on the first stage's fold
    table = {c.label: c for c in choice.candidates}
    assert table["planes"].status == "skipped", format_choice(choice)
    assert "the ladder stopped after level 1" in choice.reason
    assert choice.label == "ellipsoid"


def test_start_workers_warms_the_fits_pool_that_the_fits_then_take(monkeypatch):
    """``start_workers`` starts the fit workers at once, with the fits' threads; a fit then
    takes one of them: no other worker is started."""
    isolation.shutdown_workers()
    started = []
    make = isolation._Worker.__init__

    def counted(self, threads):
        started.append(threads)
        make(self, threads)

    monkeypatch.setattr(isolation._Worker, "__init__", counted)
    try:
        auto.start_workers(2)
        assert started == [auto.FIT_THREADS] * 2
        cloud, _ = small_sphere()
        from recon.surfaces.prepare import prepare

        result = isolation.run_isolated("convex-hull", prepare(cloud.points),
                                        threads=auto.FIT_THREADS)
        assert result["status"] == "ok" and started == [auto.FIT_THREADS] * 2
        assert sum(w.runs for w in isolation._IDLE[auto.FIT_THREADS]) == 1
    finally:
        isolation.shutdown_workers()


def test_auto_refits_its_choice_on_a_warm_fit_worker(monkeypatch):
    """``method="auto"`` starts its fit workers before it reads the cloud and refits the chosen
    run on one of them, with the fits' threads: no worker beyond the fits' is started, and the
    surface is the chosen run's fit on every point."""
    from recon import api
    from recon.surfaces import reconstruct

    isolation.shutdown_workers()
    cloud, view = small_sphere()
    started, fits = [], []
    make, fit = isolation._Worker.__init__, isolation.run_isolated

    def counted(self, threads):
        started.append(threads)
        make(self, threads)

    def watched(run, prepared, *args, **kwargs):
        fits.append((run, len(prepared.points), kwargs.get("threads")))
        return fit(run, prepared, *args, **kwargs)

    monkeypatch.setattr(isolation._Worker, "__init__", counted)
    monkeypatch.setattr(isolation, "run_isolated", watched)
    monkeypatch.setattr(reconstruct, "run_isolated", watched)
    try:
        surface = api.reconstruct(Cloud(cloud.points, cloud.attributes | dict(zip(
            ("view_x", "view_y", "view_z"), view.T, strict=True))), method="auto",
            auto_methods=["ellipsoid", "convex-hull"])
        assert started == [auto.FIT_THREADS] * auto.fit_workers()
        assert all(threads == auto.FIT_THREADS for _, _, threads in fits)
        run, n, _ = fits[-1]   # the refit: the chosen run on every point
        assert n == len(cloud.points) and run.label == surface.info["auto"]["label"]
    finally:
        isolation.shutdown_workers()


def test_the_folds_after_the_first_are_prepared_in_a_thread_then_the_callers_function():
    """``_context`` prepares the first fold at once and the others in a thread, then calls
    ``then`` there: each fold's preparation is the one made alone, array for array."""
    import threading

    import numpy as np

    from recon.surfaces import judge

    cloud, view = small_sphere()
    attributes = dict(cloud.attributes) | dict(zip(("view_x", "view_y", "view_z"), view.T,
                                                   strict=True))
    cloud = Cloud(cloud.points, attributes)
    folds = judge.pass_folds(cloud, 4, seed=0)
    seen = []
    context = auto._context(cloud, folds, k=16, fallback="centroid", seed=0,
                            then=lambda: seen.append(threading.current_thread().name))
    assert context.folds[0].ready.done()
    prepared = [fold.prepared for fold in context.folds]
    for f, made in enumerate(prepared):
        alone = auto._prepare_fold(cloud, folds, f, k=16, fallback="centroid", seed=0)
        assert np.array_equal(made.points, alone.points)
        assert np.array_equal(made.normals, alone.normals)
        assert (made.spacing, made.noise) == (alone.spacing, alone.noise)
        assert np.array_equal(made.sigma, alone.sigma)
    for _ in range(200):   # ``then`` runs after the last fold, in the same thread
        if seen:
            break
        threading.Event().wait(0.05)
    assert len(seen) == 1 and seen[0].startswith("recon-folds")


def test_a_run_failed_on_its_first_fold_is_not_fitted_on_the_others_and_chooses_alike(
        monkeypatch):
    """A model that fails on its first fold is judged failed at once; its other folds' fits,
    still waiting for a worker, are dropped (they could not change it). Its status and
    reason, every other candidate's figures, the reason and the choice are those of fitting
    it on every fold."""
    import threading

    cloud, view = small_sphere()
    monkeypatch.setattr(auto, "LADDER", ((("convex-hull", {}), ("planes", {})),
                                         (("ellipsoid", {"subdivisions": 3}),)))
    monkeypatch.setattr(auto, "ALWAYS_LEVELS", 2)
    fits: list[str] = []
    fit, drop = isolation.run_isolated, auto._drop_decided
    decided = threading.Event()

    def failing(run, prepared, *args, **kwargs):
        fits.append(run.label)
        if run.method == "convex-hull":
            return {"method": run.method, "params": run.params, "status": "failed",
                    "failure": "error", "reason": "convex-hull: qhull gave up",
                    "process_time_s": 0.0}
        decided.wait(60)   # the hull's first fold has been taken in first
        return fit(run, prepared, *args, **kwargs)

    def dropping(state, pending, bar):
        drop(state, pending, bar)
        decided.set()

    monkeypatch.setattr(isolation, "run_isolated", failing)
    monkeypatch.setattr(auto, "_drop_decided", dropping)
    options = {"view_points": view, "uncertainty": cloud.attributes, "seed": 0, "n_workers": 1}
    dropped = choose(cloud.points, **options)
    assert fits.count("convex-hull") == 1, fits
    hull = next(c for c in dropped.candidates if c.label == "convex-hull")
    assert hull.status == "failed" and hull.reason == "convex-hull: qhull gave up"

    monkeypatch.setattr(auto, "_drop_decided", lambda state, pending, bar: decided.set())
    fits.clear()
    every = choose(cloud.points, **options)
    assert fits.count("convex-hull") == 4, fits
    assert figures(every) == figures(dropped)
    assert [(c.status, c.reason) for c in every.candidates] == \
        [(c.status, c.reason) for c in dropped.candidates]
    assert every.reason == dropped.reason and every.label == dropped.label
