"""Experiments over surface methods: ``compare`` (speed against accuracy), ``stability`` (where
methods fail), ``auto`` (the choice without the truth), the Dask ``sweep`` they run on, ``charts``
(the one plotting module), ``report`` (one HTML page) and the paper's ``studies``."""
